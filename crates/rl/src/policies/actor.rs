//! [`ActorNet`]: the network of a trained policy that chooses actions, whatever algorithm
//! trained it, and [`ActorDescription`], what an exporter needs to rebuild it elsewhere.

use crate::algorithm::TensorMap;
use crate::error::Result;
use crate::policies::net_config::NetConfig;
use rand_chacha::ChaCha8Rng;

/// What turns the actor's last layer into the deterministic action.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Head {
    /// The Gaussian's mean, as it is (PPO's actor-critic).
    Mean,
    /// `tanh` of the first `act_dim` outputs: a squashed Gaussian's mode (its later outputs
    /// are log standard deviations), or a deterministic actor's squashed output.
    TanhMean,
}

/// The actor's layers as an exporter reads them: `{prefix}.l{i}.weight` and `.bias` for
/// `i` in `0..=net.net_arch.len()`, an activation after each but the last, then the head.
#[derive(Clone, Debug, PartialEq)]
pub struct ActorDescription {
    /// Name prefix of the actor's layers in `model.safetensors` (`pi`, `actor`).
    pub prefix: &'static str,
    /// Hidden layers, activation and feature extractor.
    pub net: NetConfig,
    /// The map from the last layer's output to the action.
    pub head: Head,
}

/// The network of a trained policy that acts: what [`crate::Policy`] holds.
pub trait ActorNet: Send {
    /// Actions for whole (already normalised) observations, row-major: the distribution's mode
    /// when `deterministic`, else a sample drawn from `rng`.
    fn act(&self, obs: &[f32], deterministic: bool, rng: &mut ChaCha8Rng) -> Result<Vec<f32>>;

    /// Its parameters by their names in `model.safetensors`.
    fn tensors(&self) -> TensorMap;

    /// How an exporter rebuilds it.
    fn description(&self) -> ActorDescription;
}
