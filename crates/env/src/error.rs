//! Errors of the environment layer.

use fairgrasp_sim::SimError;

#[derive(Debug, thiserror::Error)]
pub enum EnvError {
    /// An action that cannot be applied (wrong length, NaN, infinite).
    #[error("invalid action: {0}")]
    Action(String),
    /// A setting that is unknown or out of range; names the key.
    #[error("invalid setting `{key}`: {problem}")]
    Config { key: String, problem: String },
    /// The environment was used out of order (e.g. `step` before `reset`).
    #[error("{0}")]
    Usage(String),
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error("rendering: {0}")]
    Render(fairgrasp_render::RenderError),
    #[error("{path}: {problem}")]
    File { path: String, problem: String },
}

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
