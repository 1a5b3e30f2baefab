//! Errors of the deployment layer.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum DeployError {
    /// A network call failed or timed out; names the call and the address.
    #[error("{call} to {addr}: {message}")]
    Network {
        call: String,
        addr: String,
        message: String,
    },
    /// The controller answered with a non-zero error code.
    #[error("{call}: controller error {code} ({meaning})")]
    Controller {
        call: String,
        code: i64,
        meaning: String,
    },
    /// A reply or frame that does not follow the protocol.
    #[error("protocol: {0}")]
    Protocol(String),
    /// A bad file or setting, naming where.
    #[error("{what}: {message}")]
    Config { what: String, message: String },
    #[error(transparent)]
    Io(#[from] std::io::Error),
    #[error(transparent)]
    Sim(#[from] fairgrasp_sim::SimError),
    #[error(transparent)]
    Env(#[from] fairgrasp_env::EnvError),
    #[error(transparent)]
    Rl(#[from] fairgrasp_rl::error::RlError),
    #[error("{0}")]
    Other(String),
}

impl DeployError {
    pub fn config(what: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Config {
            what: what.into(),
            message: message.into(),
        }
    }
}

pub type Result<T, E = DeployError> = std::result::Result<T, E>;
