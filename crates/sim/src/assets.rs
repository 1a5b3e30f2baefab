//! The robot descriptions that ship with fairgrasp, compiled into the binary.

use crate::error::Result;
use crate::model::{LoadOptions, RobotModel};
use std::path::{Path, PathBuf};

/// The FAIRINO FR5 arm (primitive shapes; no meshes).
pub const FR5_URDF: &str = include_str!("../../../assets/robots/fr5/urdf/fr5.urdf");
/// The parallel two-finger gripper.
pub const GRIPPER_URDF: &str =
    include_str!("../../../assets/grippers/parallel/urdf/parallel_gripper.urdf");

/// The repository's `assets/` directory (for tools that want the files themselves).
pub fn assets_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets")
}

/// Path of the bundled FR5 URDF file in the source tree.
pub fn fr5_urdf_path() -> PathBuf {
    assets_dir().join("robots/fr5/urdf/fr5.urdf")
}

/// The bundled FR5 model.
pub fn fr5() -> Result<RobotModel> {
    RobotModel::from_urdf_str(
        FR5_URDF,
        "bundled fr5.urdf",
        Path::new(""),
        &LoadOptions::default(),
    )
}

/// The bundled gripper model.
pub fn parallel_gripper() -> Result<RobotModel> {
    RobotModel::from_urdf_str(
        GRIPPER_URDF,
        "bundled parallel_gripper.urdf",
        Path::new(""),
        &LoadOptions::default(),
    )
}
