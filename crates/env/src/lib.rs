//! fairgrasp-env: the FR5 grasp task as a Gymnasium-style environment.
//!
//! Layer 2 of fairgrasp (sim → **env** → rl → deploy).
//! - [`core`]: the contract ([`Env`]: `reset(seed) -> (obs, info)`,
//!   `step(action) -> (obs, reward, terminated, truncated, info)`, spaces, render modes);
//! - [`spaces`]: Gymnasium's `Box`;
//! - [`grasp`]: `FaArmGrasp-v0`, the grasp task;
//! - [`config`]: every knob, from TOML, overridable by dotted keys;
//! - [`observation`]: the `seed23` and `rich` observation layouts.

pub mod check;
pub mod config;
pub mod core;
pub mod error;
pub mod grasp;
pub mod observation;
pub mod scripted;
pub mod spaces;

pub use crate::core::{Env, EpisodeEvent, Info, Step};
pub use config::EnvConfig;
pub use error::{EnvError, Result};
pub use fairgrasp_sim as sim;
pub use grasp::{ENV_ID, GraspEnv};
