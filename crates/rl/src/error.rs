//! The error type of the learning code.

use fairgrasp_env::EnvError;

/// Errors of the learning code.
#[derive(Debug, thiserror::Error)]
pub enum RlError {
    #[error(transparent)]
    Env(#[from] EnvError),
    #[error("network: {0}")]
    Candle(#[from] candle_core::Error),
    #[error("invalid setting `{key}`: {problem}")]
    Config { key: String, problem: String },
    /// A saved model or checkpoint that cannot be used (corrupt, incomplete, mismatched).
    #[error("{0}")]
    Model(String),
    #[error("{0}")]
    Other(String),
}

pub type Result<T, E = RlError> = std::result::Result<T, E>;
