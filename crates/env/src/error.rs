//! Errors of the environment layer.

use fairgrasp_sim::SimError;

/// What can go wrong while configuring, building, stepping or saving an environment.
#[derive(Debug, thiserror::Error)]
pub enum EnvError {
    /// An action that cannot be applied (wrong length, NaN, infinite).
    #[error("invalid action: {0}")]
    Action(String),
    /// A setting that is unknown or out of range; names the key.
    #[error("invalid setting `{key}`: {problem}")]
    Config {
        /// The setting's key, e.g. `control.action_mode`.
        key: String,
        /// Why it is refused.
        problem: String,
    },
    /// The environment was used out of order (e.g. `step` before `reset`).
    #[error("{0}")]
    Usage(String),
    /// The simulation failed (a bad model or scene setting, a non-finite state, …).
    #[error(transparent)]
    Sim(#[from] SimError),
    /// Rendering failed; bad camera settings become [`EnvError::Config`] instead.
    #[error("rendering: {0}")]
    Render(fairgrasp_render::RenderError),
    /// A file (a config, saved statistics) could not be read, parsed or written.
    #[error("{path}: {problem}")]
    File {
        /// The file.
        path: String,
        /// What went wrong.
        problem: String,
    },
}

/// Result alias for the environment layer.
pub type Result<T, E = EnvError> = std::result::Result<T, E>;

impl From<fairgrasp_render::RenderError> for EnvError {
    /// Camera settings come from the `[render]` section: name the key.
    fn from(e: fairgrasp_render::RenderError) -> Self {
        match e {
            fairgrasp_render::RenderError::Camera { field, problem } => {
                EnvError::config(format!("render.{field}"), problem)
            }
            other => EnvError::Render(other),
        }
    }
}

impl EnvError {
    pub(crate) fn config(key: impl Into<String>, problem: impl Into<String>) -> Self {
        EnvError::Config {
            key: key.into(),
            problem: problem.into(),
        }
    }
}
