//! fairgrasp-env: Gymnasium-style environments for the FR5 — a tiny contract, tasks beside it.
//!
//! Layer 2 of fairgrasp (sim → **env** → rl → deploy).
//! - [`core`]: the contract ([`Env`]: `reset(seed) -> (obs, info)`,
//!   `step(action) -> (obs, reward, terminated, truncated, info)`, spaces, render modes); a
//!   task's own values travel in [`Info::extras`] and [`Info::reward_terms`] by name;
//! - [`registry`]: env ids and [`make`] (Gymnasium's `gymnasium.make`);
//! - [`arm`]: the shared base of the arm tasks — the plain [`arm::ArmState`], the action
//!   mapping, randomisation, noise — and the [`arm::Task`] hooks a task fills;
//! - [`tasks`]: `FaArmGrasp-v0`, `FaArmPickPlace-v0`, `FaArmSort-v0`, classic control;
//! - [`spaces`]: Gymnasium's `Box`;
//! - [`config`]: TOML with `section.key=value` overrides;
//! - [`vector`]: [`VecEnv`], N environments stepped in parallel with automatic resets, behind
//!   the [`VectorEnv`] interface;
//! - [`wrappers`]: [`RescaleAction`], [`RecordEpisodeStatistics`] and [`VecNormalize`], as in
//!   Gymnasium and Stable-Baselines3;
//! - [`running_stats`]: [`RunningMeanStd`], SB3's running mean and variance.

#![warn(missing_docs)]

pub mod arm;
pub mod atomic;
pub mod check;
pub mod config;
pub mod core;
pub mod error;
pub mod random;
pub mod registry;
pub mod running_stats;
pub mod scripted;
pub mod spaces;
pub mod tasks;
pub mod vector;
pub mod wrappers;

pub use crate::core::{Env, EpisodeEvent, Info, NamedValues, Step};
pub use arm::{ActionMode, ArmEnv, ArmState, ObsMode, Task};
pub use error::{EnvError, Result};
pub use fairgrasp_render as render;
pub use fairgrasp_sim as sim;
pub use registry::{EnvSpec, make};
pub use running_stats::RunningMeanStd;
pub use tasks::grasp::{ENV_ID, GraspConfig, GraspEnv};
pub use vector::{EpisodeEnd, VecEnv, VecStep, VectorEnv};
pub use wrappers::{
    EpisodeStats, RecordEpisodeStatistics, RescaleAction, VecNormalize, VecNormalizeConfig,
    VecNormalizeState,
};

/// The grasp task's configuration under its former name.
pub type EnvConfig = GraspConfig;
