//! fairgrasp-rl: reinforcement learning for the fairgrasp environments.
//!
//! Layer 3 of fairgrasp (sim → env → **rl** → deploy). Shared machinery lives here once —
//! [`buffers`] (rollout buffer with GAE, replay buffer), [`distributions`] (the Gaussian and the
//! tanh-squashed Gaussian), [`nn`] (the MLP and Adam), [`policies`] (networks built from a
//! [`policies::NetConfig`]), [`Policy`] (a saved model acting), [`logger`] (TensorBoard event
//! files and CSV) — and each algorithm ([`ppo`], [`sac`], [`td3`]) is a thin module on top,
//! listed once in [`algo`].
//!
//! Networks run on [candle](https://github.com/huggingface/candle) (CPU); a PPO update on our
//! network sizes measured 4.8 s with candle against 6.7 s with burn-ndarray, and candle builds in
//! 2.7 min against 7.8 min (docs/training.md).

#![warn(missing_docs)]

pub mod algo;
pub mod algorithm;
pub mod buffers;
pub mod configs;
pub mod distill;
pub mod distributions;
pub mod error;
pub mod evaluation;
pub mod kernels;
pub mod logger;
pub mod model;
pub mod nn;
pub mod off_policy;
pub mod policies;
pub mod policy;
pub mod ppo;
pub mod sac;
pub mod td3;
pub mod train;

pub use algo::{Algo, AlgoConfig};
pub use fairgrasp_env as env;
pub use policy::Policy;
