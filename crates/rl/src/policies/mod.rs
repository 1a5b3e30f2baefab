//! Policies (SB3's `common/policies.py`): the networks each algorithm learns, built from a
//! [`NetConfig`] (SB3's `policy_kwargs`) through a [`features::FeaturesExtractor`]. They know no
//! algorithm: the algorithms build them. A saved model acting is [`crate::Policy`].
//!
//! - [`net_config`]: [`NetConfig`], hidden layers, activation and feature extractor;
//! - [`features`]: the feature-extractor seam ([`features::FeaturesConfig`], `flatten` today);
//! - [`actor`]: [`ActorNet`], the acting network of any trained policy, and how it exports;
//! - [`actor_critic`]: PPO's Gaussian policy and value network;
//! - [`critics`]: the twin critics and Polyak-averaged targets SAC and TD3 share;
//! - [`sac_policy`]: SAC's squashed Gaussian actor with its critics;
//! - [`td3_policy`]: TD3's deterministic actor with its critics and targets.

pub mod actor;
pub mod actor_critic;
pub mod critics;
pub mod features;
pub mod net_config;
pub mod sac_policy;
pub mod td3_policy;

pub use actor::{ActorDescription, ActorNet, Head};
pub use actor_critic::{ActorCritic, PolicyOutput};
pub use critics::{CriticsWithTarget, TargetPairs, TwinCritics};
pub use features::{FeaturesConfig, FeaturesExtractor, FlattenExtractor};
pub use net_config::NetConfig;
pub use sac_policy::{SacActor, SacPolicy};
pub use td3_policy::{Td3Actor, Td3Policy};
