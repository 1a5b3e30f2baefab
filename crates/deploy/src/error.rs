//! Errors of the deployment layer.

use thiserror::Error;

/// What can go wrong in the deployment layer: the controller link, files and settings, and
/// the layers below.
#[derive(Debug, Error)]
pub enum DeployError {
    /// A network call failed or timed out; names the call and the address.
    #[error("{call} to {addr}: {message}")]
    Network {
        /// The call or step, e.g. an XML-RPC method or `UDP servo`.
        call: String,
        /// The address it was made to or listened on (`host:port`).
        addr: String,
        /// What went wrong.
        message: String,
    },
    /// The controller answered with a non-zero error code.
    #[error("{call}: controller error {code} ({meaning})")]
    Controller {
        /// The XML-RPC method or command.
        call: String,
        /// The controller's error code.
        code: i64,
        /// The code's meaning ([`crate::fairino::error_code_meaning`]).
        meaning: String,
    },
    /// A reply or frame that does not follow the protocol.
    #[error("protocol: {0}")]
    Protocol(String),
    /// A bad file or setting, naming where.
    #[error("{what}: {message}")]
    Config {
        /// The file, setting or option at fault.
        what: String,
        /// Why it is refused.
        message: String,
    },
    /// A file or socket operation failed.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The simulator failed.
    #[error(transparent)]
    Sim(#[from] fairgrasp_sim::SimError),
    /// The environment layer failed (the model's env, its settings).
    #[error(transparent)]
    Env(#[from] fairgrasp_env::EnvError),
    /// The RL layer failed (loading a model or its policy).
    #[error(transparent)]
    Rl(#[from] fairgrasp_rl::error::RlError),
    /// Anything else, with its message.
    #[error("{0}")]
    Other(String),
}

impl DeployError {
    /// A [`DeployError::Config`] naming `what`.
    pub fn config(what: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Config {
            what: what.into(),
            message: message.into(),
        }
    }
}

/// Result alias for the deployment layer.
pub type Result<T, E = DeployError> = std::result::Result<T, E>;

/// Whether a socket read or write gave up on its timeout (or would block): no data yet, not a
/// failure.
pub(crate) fn is_timeout(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
    )
}
