//! Errors of the simulation layer. Every error names the problem and where it is (file, element).

use std::path::PathBuf;

/// What can go wrong while loading a robot description or building and driving a scene.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The robot description is a xacro macro file, which must be expanded first.
    #[error(
        "{path} is a xacro file; expand it to plain URDF first, e.g. `xacro {path} > robot.urdf` \
         (ROS) or `python -m xacro {path} -o robot.urdf`"
    )]
    Xacro { path: String },
    /// The robot description is not valid URDF.
    #[error("{source_name}: {location}: {problem}")]
    Urdf {
        /// The file (or bundled asset) the description came from.
        source_name: String,
        /// The element at fault, e.g. `joint 'j2'` or `line 14, column 3`.
        location: String,
        problem: String,
    },
    /// A mesh file referenced by the description is missing, unsupported or corrupt.
    #[error("{source_name}: {location}: mesh '{uri}': {problem}")]
    Mesh {
        source_name: String,
        location: String,
        uri: String,
        problem: String,
    },
    /// A scene, controller or gripper setting is out of range.
    #[error("invalid setting `{key}`: {problem}")]
    Config { key: String, problem: String },
    /// A command given to the simulator (a joint target, a torque, a pose) is not usable.
    #[error("invalid command: {0}")]
    Command(String),
    /// Inverse kinematics found no joint vector that reaches the target within tolerance.
    #[error("inverse kinematics did not converge: {0}")]
    Ik(String),
    /// The physics state became non-finite (an explosion); the scene must be reset.
    #[error("simulation state became non-finite: {0}")]
    NonFinite(String),
}

/// Result alias for the simulation layer.
pub type Result<T, E = SimError> = std::result::Result<T, E>;

impl SimError {
    pub(crate) fn urdf(
        source_name: impl Into<String>,
        location: impl Into<String>,
        problem: impl Into<String>,
    ) -> Self {
        SimError::Urdf {
            source_name: source_name.into(),
            location: location.into(),
            problem: problem.into(),
        }
    }

    pub(crate) fn config(key: impl Into<String>, problem: impl Into<String>) -> Self {
        SimError::Config {
            key: key.into(),
            problem: problem.into(),
        }
    }
}
