//! [`NetConfig`]: the shape of a policy's networks, the one thing about them an algorithm's
//! settings choose (SB3's `policy_kwargs`).

use crate::nn::Activation;
use crate::policies::features::FeaturesConfig;

/// Hidden layers, their activation and what the networks read. Every network of a policy (actor,
/// value network, critics) takes the same shape, as in SB3 when `net_arch` is a list.
#[derive(Clone, Debug, PartialEq)]
pub struct NetConfig {
    /// Widths of the hidden layers, input side first.
    pub net_arch: Vec<usize>,
    /// The activation after each hidden layer.
    pub activation: Activation,
    /// The feature extractor the heads read from (`flatten`: the observation itself).
    pub features: FeaturesConfig,
}
