//! fairgrasp-env: the FR5 grasp task as a Gymnasium-style environment.
//!
//! Layer 2 of fairgrasp (sim → **env** → rl → deploy).
//! - [`core`]: the contract ([`Env`]: `reset(seed) -> (obs, info)`,
//!   `step(action) -> (obs, reward, terminated, truncated, info)`, spaces, render modes);
//! - [`spaces`]: Gymnasium's `Box`;
//! - [`grasp`]: `FaArmGrasp-v0`, the grasp task;
//! - [`config`]: every knob, from TOML, overridable by dotted keys;
//! - [`observation`]: the `seed23` and `rich` observation layouts;
//! - [`vector`]: [`VecEnv`], N environments stepped in parallel with automatic resets, behind
//!   the [`VectorEnv`] interface;
//! - [`wrappers`]: [`RescaleAction`], [`RecordEpisodeStatistics`] and [`VecNormalize`], as in
//!   Gymnasium and Stable-Baselines3;
//! - [`running_stats`]: [`RunningMeanStd`], SB3's running mean and variance.

pub mod check;
pub mod classic;
pub mod config;
pub mod core;
pub mod error;
pub mod grasp;
pub mod observation;
pub mod running_stats;
pub mod scripted;
pub mod spaces;
pub mod vector;
pub mod wrappers;

pub use crate::core::{Env, EpisodeEvent, Info, Step};
pub use config::EnvConfig;
pub use error::{EnvError, Result};
pub use fairgrasp_sim as sim;
pub use grasp::{ENV_ID, GraspEnv};
pub use running_stats::RunningMeanStd;
pub use vector::{EpisodeEnd, VecEnv, VecStep, VectorEnv};
pub use wrappers::{
    EpisodeStats, RecordEpisodeStatistics, RescaleAction, VecNormalize, VecNormalizeConfig,
    VecNormalizeState,
};
