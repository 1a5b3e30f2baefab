//! Policies (SB3's `common/policies.py`): the networks of each algorithm, built from its
//! configuration through a [`features::FeaturesExtractor`], and [`Policy`], a saved model
//! ready to act without its learner.
//!
//! - [`features`]: the feature-extractor seam ([`features::FeaturesConfig`], `flatten` today);
//! - [`actor_critic`]: PPO's Gaussian policy and value network;
//! - [`critics`]: the twin critics and Polyak-averaged targets SAC and TD3 share;
//! - [`sac_policy`]: SAC's squashed Gaussian actor with its critics;
//! - [`td3_policy`]: TD3's deterministic actor with its critics and targets;
//! - [`policy`]: [`Policy`], for evaluation, deployment and the trainer's own evaluation.

pub mod actor_critic;
pub mod critics;
pub mod features;
pub mod policy;
pub mod sac_policy;
pub mod td3_policy;

pub use actor_critic::{ActorCritic, PolicyOutput};
pub use critics::{CriticsWithTarget, TargetPairs, TwinCritics};
pub use features::{FeaturesConfig, FeaturesExtractor, FlattenExtractor};
pub use policy::Policy;
pub use sac_policy::{SacActor, SacPolicy};
pub use td3_policy::{Td3Actor, Td3Policy};
