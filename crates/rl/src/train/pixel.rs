//! A run of `[pixel_ppo]` (end-to-end PPO on camera images, [`crate::ppo::pixel`]): the
//! config's environments, the camera policy saved as a model in `<run dir>/final`, played on
//! held-out episodes, and `summary.json` with the time split.

use super::{HELD_OUT_SEED_BASE, RunDir, TrainConfig, peak_memory_mib};
use crate::algo::AlgoConfig;
use crate::distill::evaluate_student;
use crate::error::{Result, RlError};
use crate::model::{FORMAT_VERSION, ModelMeta, PixelActorMeta, save_model};
use crate::policies::pixel_actor::PixelActor;
use crate::policy::Policy;
use crate::ppo::pixel::{PixelIteration, train_pixel_ppo};
use fairgrasp_env::atomic;
use fairgrasp_env::wrappers::{RescaleAction, VecNormalize};
use fairgrasp_env::{Env, VecEnv, VectorEnv, registry};
use serde::Serialize;
use std::ops::ControlFlow;
use std::path::Path;
use std::time::Instant;

/// What a `[pixel_ppo]` run did (written as `summary.json`).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PixelSummary {
    /// Environment steps trained.
    pub num_timesteps: u64,
    /// Wall time of the training (s), and its parts: stepping the environments (physics and
    /// rendering), the rollout's forward passes, the updates.
    pub seconds: f64,
    /// See [`Self::seconds`].
    pub env_seconds: f64,
    /// See [`Self::seconds`].
    pub act_seconds: f64,
    /// See [`Self::seconds`].
    pub update_seconds: f64,
    /// The actor's forward, and backward with Adam, within the updates.
    pub forward_seconds: f64,
    /// See [`Self::forward_seconds`].
    pub backward_seconds: f64,
    /// Peak resident memory of the process (MiB), where the system reports it.
    pub peak_memory_mib: Option<f64>,
    /// Held-out episodes the policy played at the end, and how many succeeded.
    pub episodes: u32,
    /// See [`Self::episodes`].
    pub successes: u32,
    /// The actor's trained values.
    pub parameters: usize,
}

/// Trains `config`'s camera policy end to end (it must have `[pixel_ppo]` and `algo = "ppo"`),
/// saves it in `run_dir/final` and evaluates it there. `on_iteration` sees every iteration and
/// may stop the run (as may `max_seconds`).
pub fn run_pixel_ppo(
    config: &TrainConfig,
    run_dir: &Path,
    on_iteration: &mut dyn FnMut(&PixelIteration) -> ControlFlow<()>,
) -> Result<(PixelSummary, Policy)> {
    config.validate()?;
    let (AlgoConfig::Ppo(ppo), Some(pixel)) = (&config.algo, &config.pixel_ppo) else {
        return Err(RlError::Config {
            key: "pixel_ppo".into(),
            problem: "end-to-end camera training needs algo = \"ppo\" and a [pixel_ppo] table"
                .into(),
        });
    };
    let io = |e: std::io::Error| RlError::Other(format!("{}: {e}", run_dir.display()));
    std::fs::create_dir_all(run_dir).map_err(io)?;
    let effective = toml::to_string(config).map_err(|e| RlError::Other(e.to_string()))?;
    atomic::write(&RunDir::new(run_dir).config(), effective.as_bytes()).map_err(io)?;
    let envs = (0..config.n_envs)
        .map(|_| {
            Ok(RescaleAction::new(registry::make(
                &config.env_id,
                &config.env,
            )?)?)
        })
        .collect::<Result<Vec<_>>>()?;
    // The actor standardises its state input itself; rewards are scaled as configured.
    let mut normalize = config.normalize.clone();
    normalize.norm_obs = false;
    let mut envs = VecNormalize::new(VecEnv::new(envs, config.threads)?, normalize)?;
    let started = Instant::now();
    let mut summary = PixelSummary::default();
    let mut watch = |it: &PixelIteration, _: &PixelActor| {
        summary.num_timesteps = it.timesteps;
        summary.env_seconds += it.env_seconds;
        summary.act_seconds += it.act_seconds;
        summary.update_seconds += it.update_seconds;
        summary.forward_seconds += it.forward_seconds;
        summary.backward_seconds += it.backward_seconds;
        let over_time = config
            .max_seconds
            .is_some_and(|s| started.elapsed().as_secs_f64() >= s);
        if over_time {
            return ControlFlow::Break(());
        }
        on_iteration(it)
    };
    let actor = train_pixel_ppo(
        &mut envs,
        ppo,
        pixel,
        config.total_timesteps,
        config.seed,
        &mut watch,
    )?;
    envs.close();
    summary.seconds = started.elapsed().as_secs_f64();
    let final_dir = RunDir::new(run_dir).final_model();
    let meta = ModelMeta {
        format_version: FORMAT_VERSION,
        algo: config.algo.clone(),
        obs_dim: actor.state_dim(),
        act_dim: actor.act_dim(),
        env_id: config.env_id.clone(),
        env: serde_json::to_value(&config.env).map_err(|e| RlError::Other(e.to_string()))?,
        normalization: None,
        num_timesteps: summary.num_timesteps,
        train_seed: config.seed,
        n_envs: config.n_envs,
        privileged_dim: 0,
        pixel_actor: Some(PixelActorMeta {
            actor: pixel.actor.clone(),
            images: actor.images().clone(),
        }),
    };
    save_model(&final_dir, &actor.weights(), &meta)?;
    let mut policy = Policy::load(&final_dir)?;
    let mut env = RescaleAction::new(registry::make(&config.env_id, &config.env)?)?;
    summary.successes = evaluate_student(
        &mut policy,
        &mut env,
        pixel.eval_episodes,
        HELD_OUT_SEED_BASE,
    )?;
    env.close();
    summary.episodes = pixel.eval_episodes;
    summary.parameters = actor.parameter_count();
    summary.peak_memory_mib = peak_memory_mib();
    let json = serde_json::to_string_pretty(&summary).map_err(|e| RlError::Other(e.to_string()))?;
    let path = run_dir.join("summary.json");
    atomic::write(&path, json.as_bytes())
        .map_err(|e| RlError::Other(format!("{}: {e}", path.display())))?;
    Ok((summary, policy))
}
