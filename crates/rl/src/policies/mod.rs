//! Policies (SB3's `common/policies.py`): the networks each algorithm learns, built from a
//! [`NetConfig`] (SB3's `policy_kwargs`) through a [`features::FeaturesExtractor`]. They know no
//! algorithm: the algorithms build them. A saved model acting is [`crate::Policy`].
//!
//! - [`net_config`]: [`NetConfig`], hidden layers, activation and feature extractor;
//! - [`features`]: the feature-extractor seam ([`features::FeaturesConfig`], `flatten` today);
//! - [`actor`]: [`ActorNet`], the acting network of any trained policy, and how it exports;
//! - [`actor_critic`]: a Gaussian policy and its value network (PPO's);
//! - [`critics`]: twin Q critics and their Polyak-averaged targets;
//! - [`squashed_gaussian`]: a tanh-squashed Gaussian actor with twin critics (SAC's);
//! - [`deterministic`]: a deterministic actor with twin critics and a target actor (TD3's).

pub mod actor;
pub mod actor_critic;
pub mod cnn;
pub mod critics;
pub mod deterministic;
pub mod features;
pub mod net_config;
pub mod pixel_actor;
pub mod squashed_gaussian;

pub use actor::{ActorDescription, ActorNet, Head};
pub use actor_critic::{ActorCritic, PolicyOutput};
pub use critics::{CriticsWithTarget, TargetPairs, TwinCritics};
pub use deterministic::{DeterministicActor, DeterministicPolicy};
pub use features::{FeaturesConfig, FeaturesExtractor, FlattenExtractor};
pub use net_config::NetConfig;
pub use squashed_gaussian::{SquashedGaussianActor, SquashedGaussianPolicy};
