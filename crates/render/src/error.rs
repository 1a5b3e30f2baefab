//! Errors of the renderer.

use std::path::PathBuf;

/// What can go wrong when setting up a camera, rendering or writing an image.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A camera setting is out of range; `field` names it (`fov_deg`, `width`, …).
    #[error("camera {field}: {problem}")]
    Camera {
        /// The setting's name.
        field: &'static str,
        /// Why its value is refused.
        problem: String,
    },
    /// The scene has more parts than the segmentation ids have room for.
    #[error("segmentation: {0}")]
    Segmentation(String),
    /// A video could not be encoded.
    #[error("video: {0}")]
    Video(String),
    /// An image file could not be written.
    #[error("cannot write {path}: {problem}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why: the I/O or encoder error, or image data of the wrong size.
        problem: String,
    },
}

impl RenderError {
    pub(crate) fn camera(field: &'static str, problem: impl Into<String>) -> Self {
        Self::Camera {
            field,
            problem: problem.into(),
        }
    }
}

/// Result alias for the renderer.
pub type Result<T, E = RenderError> = std::result::Result<T, E>;
