//! The error type of the learning code.

use fairgrasp_env::EnvError;

/// Errors of the learning code.
#[derive(Debug, thiserror::Error)]
pub enum RlError {
    /// An environment failed.
    #[error(transparent)]
    Env(#[from] EnvError),
    /// A network (candle) operation failed.
    #[error("network: {0}")]
    Candle(#[from] candle_core::Error),
    /// A bad setting (unparsable, unknown, out of range, unusable with the environment); names
    /// the key.
    #[error("invalid setting `{key}`: {problem}")]
    Config {
        /// The setting's key, e.g. `ppo.batch_size`.
        key: String,
        /// Why it is refused.
        problem: String,
    },
    /// A saved model or checkpoint that cannot be used (corrupt, incomplete, mismatched).
    #[error("{0}")]
    Model(String),
    /// Any other failure (file I/O, a missing network parameter, …), in words.
    #[error("{0}")]
    Other(String),
}

/// Result alias for the learning code.
pub type Result<T, E = RlError> = std::result::Result<T, E>;

/// Checks of one config section's settings (`[sac]`, …), each error naming `{section}.{key}`.
pub(crate) struct ConfigSection(pub &'static str);

impl ConfigSection {
    /// The error for a bad `{section}.{key}`.
    pub fn bad(&self, key: &str, problem: String) -> Result<()> {
        Err(RlError::Config {
            key: format!("{}.{key}", self.0),
            problem,
        })
    }

    pub fn positive<T: Copy + Into<f64> + std::fmt::Display>(&self, key: &str, v: T) -> Result<()> {
        if !(v.into().is_finite() && v.into() > 0.0) {
            return self.bad(key, format!("must be positive, got {v}"));
        }
        Ok(())
    }

    pub fn non_negative(&self, key: &str, v: f32) -> Result<()> {
        if !(v.is_finite() && v >= 0.0) {
            return self.bad(key, format!("must be non-negative, got {v}"));
        }
        Ok(())
    }

    pub fn at_least_one(&self, key: &str, v: usize) -> Result<()> {
        if v == 0 {
            return self.bad(key, "must be at least 1".into());
        }
        Ok(())
    }

    pub fn in_unit_interval(&self, key: &str, v: f32) -> Result<()> {
        if !(0.0..=1.0).contains(&v) {
            return self.bad(key, format!("must be in [0, 1], got {v}"));
        }
        Ok(())
    }

    /// Hidden layers, as every algorithm's `net_arch` lists them.
    pub fn net_arch(&self, net_arch: &[usize]) -> Result<()> {
        if net_arch.is_empty() || net_arch.contains(&0) {
            return self.bad(
                "net_arch",
                "needs at least one hidden layer, all of positive width".into(),
            );
        }
        Ok(())
    }
}
