//! The training run: environments, the learner, and the callbacks between its iterations —
//! what SB3's `learn()` does with its callbacks. The built-in callbacks ([`callbacks`]) log,
//! evaluate and keep the best model, stop on success, write checkpoints and keep the time
//! budget; a caller adds its own ([`train_with`]).
//!
//! - [`config`]: [`TrainConfig`], what defines a run;
//! - [`run_dir`]: [`RunDir`], the run directory's layout, checkpoints included;
//! - [`callbacks`]: the [`Callback`] trait and the built-in callbacks.

pub mod callbacks;
pub mod config;
pub mod pixel;
pub mod run_dir;

use crate::algo::{LearnerShape, LearnerVisitor};
use crate::algorithm::{Algorithm, TensorMap};
use crate::error::{Result, RlError};
pub use crate::evaluation::{
    Actor, EvalResult, evaluate, evaluate_parallel, record_episode, wilson_lower_bound,
};
use crate::logger::{CsvLogger, TensorBoardWriter};
use crate::model::{ModelMeta, save_model};
pub use callbacks::{Callback, CallbackContext, Progress, RunState, StopReason};
use callbacks::{
    Evaluate, LearnerSnapshot, LogScalars, Logs, OnProgress, SaveCheckpoint, StopOnSuccess,
    TimeBudget,
};
pub use config::{
    EVAL_SEED_BASE, EvalConfig, HELD_OUT_SEED_BASE, TrainConfig, VALIDATION_SEED_BASE,
};
use fairgrasp_env::atomic;
use fairgrasp_env::wrappers::{EpisodeStats, RescaleAction, VecNormalize, VecNormalizeState};
use fairgrasp_env::{Env, NamedValues, VecEnv, VectorEnv, registry};
use run_dir::Checkpoint;
pub use run_dir::RunDir;
use serde::{Deserialize, Serialize};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Summary of a finished run (also written to `summary.json` in the run directory).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct TrainSummary {
    /// The algorithm's name (`"ppo"`, `"sac"`, `"td3"`).
    pub algo: String,
    /// Environment steps trained, at the end.
    pub num_timesteps: u64,
    /// Wall time of the whole run, across resumes.
    pub seconds: f64,
    /// Environment steps per second of this session, updates and evaluations included.
    pub fps: f64,
    /// Peak resident memory of the process (MiB), where the system reports it.
    pub peak_memory_mib: Option<f64>,
    /// The best evaluation (by confirmed, success rate, return).
    pub best: Option<EvalResult>,
    /// The run directory.
    pub run_dir: PathBuf,
    /// The step the run resumed from, if it did.
    pub resumed_from: Option<u64>,
    /// Whether the run stopped early at the evaluation success threshold.
    pub reached_threshold: bool,
    /// Whether a caller's callback stopped the run ([`train_until`], [`train_with`]: Ctrl-C in
    /// Python, a Ray Tune scheduler).
    #[serde(default)]
    pub stopped: bool,
}

/// Peak resident set size of this process in MiB (Linux: `VmHWM`).
pub fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// Trains as configured, writing everything to `run_dir`.
pub fn train(
    config: &TrainConfig,
    run_dir: &Path,
    mut on_progress: impl FnMut(&Progress),
) -> Result<TrainSummary> {
    train_until(config, run_dir, |p| {
        on_progress(p);
        ControlFlow::Continue(())
    })
}

/// [`train`], where the progress callback may stop the run: on `Break` the loop ends after that
/// iteration and the final model, logs and summary are written as at the end of a run.
pub fn train_until(
    config: &TrainConfig,
    run_dir: &Path,
    on_progress: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<TrainSummary> {
    train_with(config, run_dir, vec![Box::new(OnProgress(on_progress))])
}

/// Trains as configured with `callbacks` run after the built-in ones at every iteration, in
/// order; any of them may stop the run.
pub fn train_with<'c>(
    config: &TrainConfig,
    run_dir: &Path,
    callbacks: Vec<Box<dyn Callback + 'c>>,
) -> Result<TrainSummary> {
    config.validate()?;
    if config.pixel_ppo.is_some() {
        return Err(RlError::Config {
            key: "pixel_ppo".into(),
            problem: "a camera policy trained end to end runs through `fairgrasp train` \
                      (train::pixel::run_pixel_ppo), not this state-policy loop"
                .into(),
        });
    }
    let dir = RunDir::new(run_dir);
    let io = |e: std::io::Error| RlError::Other(format!("{}: {e}", run_dir.display()));
    std::fs::create_dir_all(run_dir).map_err(io)?;
    let effective = toml::to_string(config).map_err(|e| RlError::Other(e.to_string()))?;
    atomic::write(&dir.config(), effective.as_bytes()).map_err(io)?;
    dispatch(config, dir, None, callbacks)
}

/// Continues the run in `run_dir` from its latest complete checkpoint, with the configuration
/// saved there (`overrides` may change keys such as `total_timesteps`). Optimiser state,
/// normalisation statistics, random streams, step counter, best result and wall time carry
/// over; the environments start fresh episodes (seeded from the step count), so the resumed
/// run matches an uninterrupted one in expectation, not bit for bit.
pub fn resume(
    run_dir: &Path,
    overrides: &[String],
    mut on_progress: impl FnMut(&Progress),
) -> Result<TrainSummary> {
    resume_until(run_dir, overrides, |p| {
        on_progress(p);
        ControlFlow::Continue(())
    })
}

/// [`resume`], where the progress callback may stop the run (see [`train_until`]).
pub fn resume_until(
    run_dir: &Path,
    overrides: &[String],
    on_progress: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<TrainSummary> {
    resume_with(run_dir, overrides, vec![Box::new(OnProgress(on_progress))])
}

/// [`resume`] with `callbacks` (see [`train_with`]).
pub fn resume_with<'c>(
    run_dir: &Path,
    overrides: &[String],
    callbacks: Vec<Box<dyn Callback + 'c>>,
) -> Result<TrainSummary> {
    let dir = RunDir::new(run_dir);
    let config_path = dir.config();
    let text = std::fs::read_to_string(&config_path).map_err(|e| {
        RlError::Model(format!(
            "cannot resume {}: {}: {e}",
            run_dir.display(),
            config_path.display()
        ))
    })?;
    let config = TrainConfig::from_toml_str(&text, overrides)?;
    let checkpoint = dir
        .checkpoints()
        .pop()
        .map(|(_, path)| path)
        .ok_or_else(|| {
            RlError::Model(format!(
                "cannot resume {}: no complete checkpoint in {}",
                run_dir.display(),
                dir.checkpoints_dir().display()
            ))
        })?;
    if !overrides.is_empty() {
        let effective = toml::to_string(&config).map_err(|e| RlError::Other(e.to_string()))?;
        atomic::write(&config_path, effective.as_bytes())
            .map_err(|e| RlError::Other(format!("{}: {e}", config_path.display())))?;
    }
    dispatch(&config, dir, Some(checkpoint), callbacks)
}

/// The checkpoint directories of a run, oldest first (incomplete ones are skipped).
pub fn checkpoints(run_dir: &Path) -> Vec<(u64, PathBuf)> {
    RunDir::new(run_dir).checkpoints()
}

type TrainVecEnv = VecNormalize<VecEnv<RescaleAction<Box<dyn Env>>>>;

fn dispatch<'c>(
    config: &TrainConfig,
    run_dir: RunDir,
    checkpoint: Option<PathBuf>,
    callbacks: Vec<Box<dyn Callback + 'c>>,
) -> Result<TrainSummary> {
    let envs = (0..config.n_envs)
        .map(|_| registry::make(&config.env_id, &config.env).and_then(RescaleAction::new))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    let venv = VecNormalize::new(VecEnv::new(envs, config.threads)?, config.normalize.clone())?;
    let shape = LearnerShape {
        obs_dim: venv.obs_dim(),
        act_dim: venv.act_dim(),
        privileged_dim: venv.privileged_dim(),
        n_envs: config.n_envs,
        seed: config.seed,
        threads: config.threads,
    };
    let run = Run {
        config,
        run_dir,
        venv,
        checkpoint,
        callbacks,
    };
    config.algo.build(shape, run)
}

/// A training run waiting for its learner.
struct Run<'a, 'c> {
    config: &'a TrainConfig,
    run_dir: RunDir,
    venv: TrainVecEnv,
    checkpoint: Option<PathBuf>,
    callbacks: Vec<Box<dyn Callback + 'c>>,
}

impl LearnerVisitor for Run<'_, '_> {
    type Output = TrainSummary;

    fn visit<A: Algorithm>(self, learner: A) -> Result<TrainSummary> {
        run(self, learner)
    }
}

/// The learner and its environments, as callbacks read them.
struct Snapshot<'a, A> {
    algo: &'a A,
    venv: &'a TrainVecEnv,
    config: &'a TrainConfig,
    env_json: &'a serde_json::Value,
    privileged_dim: usize,
}

impl<A: Algorithm> LearnerSnapshot for Snapshot<'_, A> {
    fn meta(&self) -> ModelMeta {
        let (config, venv) = (self.config, self.venv);
        ModelMeta {
            format_version: crate::model::FORMAT_VERSION,
            algo: config.algo.clone(),
            obs_dim: venv.obs_dim(),
            act_dim: venv.act_dim(),
            env_id: config.env_id.clone(),
            env: self.env_json.clone(),
            normalization: config.normalize.norm_obs.then(|| venv.state().to_json()),
            num_timesteps: self.algo.num_timesteps(),
            train_seed: config.seed,
            n_envs: config.n_envs,
            privileged_dim: self.privileged_dim,
            pixel_actor: None,
        }
    }

    fn weights(&self) -> Result<TensorMap> {
        self.algo.weights()
    }

    fn training_state(&self) -> Result<TensorMap> {
        self.algo.training_state()
    }

    fn normalization(&self) -> String {
        self.venv.state().to_json()
    }
}

/// The training loop shared by every algorithm.
fn run<A: Algorithm>(run: Run<'_, '_>, mut algo: A) -> Result<TrainSummary> {
    let Run {
        config,
        run_dir,
        mut venv,
        checkpoint,
        callbacks: mut user_callbacks,
    } = run;
    let io = |e: std::io::Error| RlError::Other(format!("{}: {e}", run_dir.path().display()));
    let mut state = RunState {
        next_eval: config.eval.freq,
        next_checkpoint: config.checkpoint_freq,
        ..RunState::default()
    };
    let mut elapsed_before = 0.0;
    let mut resumed_from = None;
    let mut csv = CsvLogger::open(run_dir.path()).map_err(io)?;

    if let Some(dir) = &checkpoint {
        let Checkpoint {
            trainer,
            meta,
            weights,
            training,
        } = Checkpoint::read(dir)?;
        meta.check_compatible(config.algo.algo(), venv.obs_dim(), venv.act_dim())?;
        algo.load_weights(&weights)?;
        algo.load_training_state(&training)?;
        algo.set_num_timesteps(trainer.num_timesteps);
        let normalization = VecNormalizeState::from_json(&trainer.normalization).map_err(|p| {
            RlError::Model(format!("{}: {p}", dir.join("trainer_state.json").display()))
        })?;
        venv.set_state(normalization)?;
        state.recent.extend(trainer.recent_episodes);
        state.best = trainer.best;
        state.next_eval = trainer.next_eval;
        state.next_checkpoint = trainer.next_checkpoint;
        elapsed_before = trainer.elapsed_seconds;
        resumed_from = Some(trainer.num_timesteps);
        // Rows logged after the checkpoint belong to the interrupted attempt.
        csv.truncate_after("time/total_timesteps", trainer.num_timesteps as f64)
            .map_err(io)?;
        // Fresh episodes, on streams that depend on where the run stands.
        let reseed = config
            .seed
            .wrapping_add(trainer.num_timesteps.wrapping_mul(0x9e37_79b9_7f4a_7c15));
        venv.reset(Some(reseed))?;
    } else {
        venv.reset(Some(config.seed))?;
    }
    let mut logs = Logs {
        tensorboard: TensorBoardWriter::create(&run_dir.tensorboard()).map_err(io)?,
        csv,
    };
    let env_json = serde_json::to_value(&config.env).map_err(|e| RlError::Other(e.to_string()))?;
    let privileged_dim = match config.algo.privileged_critic() {
        true => venv.privileged_dim(),
        false => 0,
    };

    let started = Instant::now();
    let start_steps = algo.num_timesteps();
    let mut builtin: Vec<Box<dyn Callback>> = vec![
        Box::new(LogScalars::new(algo.log_interval(), start_steps)),
        Box::new(Evaluate),
        Box::new(StopOnSuccess),
        Box::new(SaveCheckpoint),
    ];
    let mut last: Vec<Box<dyn Callback>> = Vec::new();
    if let Some(seconds) = config.max_seconds {
        last.push(Box::new(TimeBudget { seconds }));
    }
    let mut progress = Progress {
        total_timesteps: config.total_timesteps,
        best_success_rate: state.best.as_ref().map(|b| b.success_rate),
        ..Progress::default()
    };
    let mut stops: Vec<StopReason> = Vec::new();
    while algo.num_timesteps() < config.total_timesteps && stops.is_empty() {
        let remaining = 1.0 - algo.num_timesteps() as f64 / config.total_timesteps as f64;
        let recent = &mut state.recent;
        let mut on_step = |step: &fairgrasp_env::VecStep<'_>| {
            for end in step.episode_ends.iter().flatten() {
                if recent.len() == 100 {
                    recent.pop_front();
                }
                recent.push_back(end.episode.clone());
            }
            for callback in user_callbacks.iter_mut() {
                callback.on_step(step);
            }
        };
        let train_scalars = algo.learn_iteration(&mut venv, remaining, &mut on_step)?;
        let steps = algo.num_timesteps();
        progress.num_timesteps = steps;
        progress.fps = (steps - start_steps) as f64 / started.elapsed().as_secs_f64().max(1e-9);
        update_rollout_stats(&mut progress, &state.recent);

        let snapshot = Snapshot {
            algo: &algo,
            venv: &venv,
            config,
            env_json: &env_json,
            privileged_dim,
        };
        let mut ctx = CallbackContext {
            config,
            run_dir: &run_dir,
            num_timesteps: steps,
            progress: &mut progress,
            state: &mut state,
            logs: &mut logs,
            train_scalars: &train_scalars,
            learner: &snapshot,
            started,
            elapsed_before,
        };
        for callback in builtin.iter_mut() {
            if let ControlFlow::Break(reason) = callback.on_iteration(&mut ctx)? {
                stops.push(reason);
            }
        }
        ctx.logs.tensorboard.flush().map_err(io)?;
        for callback in user_callbacks.iter_mut().chain(last.iter_mut()) {
            if let ControlFlow::Break(reason) = callback.on_iteration(&mut ctx)? {
                stops.push(reason);
            }
        }
    }
    let snapshot = Snapshot {
        algo: &algo,
        venv: &venv,
        config,
        env_json: &env_json,
        privileged_dim,
    };
    save_model(&run_dir.final_model(), &algo.weights()?, &snapshot.meta())?;
    logs.tensorboard.flush().map_err(io)?;
    let session = started.elapsed().as_secs_f64();
    let summary = TrainSummary {
        algo: algo.name().into(),
        num_timesteps: algo.num_timesteps(),
        seconds: elapsed_before + session,
        fps: (algo.num_timesteps() - start_steps) as f64 / session.max(1e-9),
        peak_memory_mib: peak_memory_mib(),
        best: state.best,
        run_dir: run_dir.path().to_path_buf(),
        resumed_from,
        reached_threshold: stops.contains(&StopReason::SuccessThreshold),
        stopped: stops.contains(&StopReason::Requested),
    };
    let json = serde_json::to_string_pretty(&summary).map_err(|e| RlError::Other(e.to_string()))?;
    atomic::write(&run_dir.summary(), json.as_bytes()).map_err(io)?;
    Ok(summary)
}

/// The rollout statistics of `progress` from the recent episodes.
fn update_rollout_stats(
    progress: &mut Progress,
    recent: &std::collections::VecDeque<EpisodeStats>,
) {
    if recent.is_empty() {
        return;
    }
    let n = recent.len() as f32;
    let mean = |f: fn(&EpisodeStats) -> f32| recent.iter().map(f).sum::<f32>() / n;
    progress.ep_rew_mean = Some(mean(|e| e.episode_return as f32));
    progress.rollout_success_rate = Some(mean(|e| e.success as u8 as f32));
    let mut sums = NamedValues::new();
    for e in recent {
        for (name, value) in e.max_extras.iter() {
            let sum = sums.get(name).unwrap_or(0.0) + value;
            sums.set(name.to_string(), sum);
        }
    }
    progress.rollout_max_extras.clear();
    for (name, sum) in sums.iter() {
        progress.rollout_max_extras.set(name.to_string(), sum / n);
    }
}
