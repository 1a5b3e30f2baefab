//! The training run: environments, the algorithm (PPO or SAC), evaluation with best-model
//! saving, checkpoints and resume, TensorBoard and CSV logs — what SB3's `learn()` with
//! `EvalCallback` and `CheckpointCallback` gives, in one driver.
//!
//! A run directory holds `config.toml` (the effective configuration), `tb/` (TensorBoard event
//! files), `progress.csv`, `best/` (the best model by evaluation success rate, then return),
//! `final/` and `checkpoints/step_<N>/` (a model plus `training_state.safetensors` and
//! `trainer_state.json`: what [`resume`] needs to continue).

use crate::algorithm::{Algorithm, TensorMap};
use crate::error::{Result, RlError};
pub use crate::evaluation::{Actor, EvalResult, evaluate, evaluate_parallel, record_episode};
use crate::logger::{CsvLogger, TensorBoardWriter};
use crate::model::{
    ModelMeta, load_tensors, replace_dir, save_model, save_tensors, write_model_files,
};
use crate::policies::Policy;
use crate::ppo::{Ppo, PpoConfig};
use crate::sac::{Sac, SacConfig};
use crate::td3::{Td3, Td3Config};
use fairgrasp_env::atomic;
use fairgrasp_env::wrappers::{
    EpisodeStats, RescaleAction, VecNormalize, VecNormalizeConfig, VecNormalizeState,
};
use fairgrasp_env::{Env, NamedValues, VecEnv, VectorEnv, registry};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Which algorithm learns.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Algo {
    #[default]
    Ppo,
    Sac,
    Td3,
}

impl Algo {
    /// Every algorithm, in the order help texts list them.
    pub const ALL: [Algo; 3] = [Algo::Ppo, Algo::Sac, Algo::Td3];

    /// The name configs, saved models and the command line use.
    pub fn as_str(self) -> &'static str {
        match self {
            Algo::Ppo => "ppo",
            Algo::Sac => "sac",
            Algo::Td3 => "td3",
        }
    }
}

impl std::fmt::Display for Algo {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for Algo {
    type Err = RlError;

    fn from_str(name: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|a| a.as_str() == name)
            .ok_or_else(|| RlError::Config {
                key: "algo".into(),
                problem: format!(
                    "unknown algorithm `{name}` (one of {})",
                    Self::ALL.map(Algo::as_str).join(", ")
                ),
            })
    }
}

/// Evaluation during training (like SB3's `EvalCallback`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvalConfig {
    /// Evaluate every this many environment steps (0: never).
    pub freq: u64,
    pub episodes: u32,
    /// Stop training once the evaluation success rate reaches this (and, with
    /// `confirm_episodes`, the confirmation holds).
    pub success_threshold: Option<f32>,
    /// When an evaluation reaches `success_threshold`, play this many more episodes on
    /// validation seeds of their own ([`VALIDATION_SEED_BASE`]) before stopping (0: stop at
    /// once). The best model is then the one with the best confirmed success, so neither the
    /// stop nor the choice rests on the seeds that triggered it.
    pub confirm_episodes: u32,
    /// Stop only when the 95 % Wilson lower bound of the confirmation's success rate reaches
    /// this (of 200 episodes: 197 successes give 0.957, 196 give 0.9497, 200 give 0.981).
    pub confirm_lower_bound: f32,
    /// After each evaluation, play its first episode again with the `[render]` camera and
    /// write it as `videos/eval_<steps>.gif` in the run directory (arm tasks).
    pub record: bool,
    /// Width and height of those videos.
    pub record_size: [u32; 2],
    /// Settings laid over the training env's for the evaluations and confirmations (SB3's
    /// separate `eval_env`): e.g. the nominal scene, without the training's draws, so that the
    /// stop rule measures the world the model is deployed to. Empty: the training env.
    pub env: toml::Table,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            freq: 50_000,
            episodes: 20,
            success_threshold: None,
            confirm_episodes: 0,
            confirm_lower_bound: 0.95,
            record: false,
            record_size: [320, 240],
            env: toml::Table::new(),
        }
    }
}

/// Seeds of the evaluations during training: `EVAL_SEED_BASE + episode`. Training episodes
/// draw from the streams seeded `seed … seed + n_envs`; `fairgrasp eval` defaults to
/// [`HELD_OUT_SEED_BASE`], so the final figure is measured on episodes that neither trained
/// the policy nor chose the best model.
pub const EVAL_SEED_BASE: u64 = 1_000_000;
/// Default first seed of `fairgrasp eval`.
pub const HELD_OUT_SEED_BASE: u64 = 2_000_000_000;
/// Seeds of the confirmation evaluations (`eval.confirm_episodes`): apart from the training,
/// evaluation and held-out seeds.
pub const VALIDATION_SEED_BASE: u64 = 1_500_000_000;

/// The lower end of the 95 % Wilson score interval for `successes` of `n` (0 when `n` is 0).
pub fn wilson_lower_bound(successes: u32, n: u32) -> f64 {
    if n == 0 {
        return 0.0;
    }
    let (n, z) = (n as f64, 1.959_963_985);
    let p = successes as f64 / n;
    let centre = p + z * z / (2.0 * n);
    let margin = z * ((p * (1.0 - p) + z * z / (4.0 * n)) / n).sqrt();
    (centre - margin) / (1.0 + z * z / n)
}

/// Everything that defines a training run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// The registered environment to learn (`fairgrasp env list`).
    pub env_id: String,
    pub algo: Algo,
    pub total_timesteps: u64,
    pub seed: u64,
    /// Parallel environments.
    pub n_envs: usize,
    /// Threads stepping them.
    pub threads: usize,
    /// Save a checkpoint every this many environment steps (0: never).
    pub checkpoint_freq: u64,
    /// Stop after this much wall time (s), across resumes (a time budget for benchmarks).
    pub max_seconds: Option<f64>,
    pub normalize: VecNormalizeConfig,
    pub eval: EvalConfig,
    pub ppo: PpoConfig,
    pub sac: SacConfig,
    pub td3: Td3Config,
    /// The environment's own settings (its TOML table; missing keys take their defaults).
    pub env: toml::Table,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            env_id: fairgrasp_env::ENV_ID.into(),
            algo: Algo::Ppo,
            total_timesteps: 2_000_000,
            seed: 42,
            n_envs: 4,
            threads: 2,
            checkpoint_freq: 200_000,
            max_seconds: None,
            normalize: VecNormalizeConfig::default(),
            eval: EvalConfig::default(),
            ppo: PpoConfig::default(),
            sac: SacConfig::default(),
            td3: Td3Config::default(),
            env: toml::Table::new(),
        }
    }
}

impl TrainConfig {
    /// Parses TOML, applies `section.key=value` overrides, validates; errors name the key.
    pub fn from_toml_str(text: &str, overrides: &[String]) -> Result<Self> {
        let mut table: toml::Table =
            text.parse().map_err(|e: toml::de::Error| RlError::Config {
                key: "(file)".into(),
                problem: e.to_string(),
            })?;
        for item in overrides {
            fairgrasp_env::config::apply_override(&mut table, item)?;
        }
        let text = toml::to_string(&table).map_err(|e| RlError::Other(e.to_string()))?;
        let config: TrainConfig = toml::from_str(&text).map_err(|e| RlError::Config {
            key: "config".into(),
            problem: e.to_string(),
        })?;
        config.validate()?;
        Ok(config)
    }

    pub fn validate(&self) -> Result<()> {
        let bad = |key: &str, problem: &str| {
            Err(RlError::Config {
                key: key.into(),
                problem: problem.into(),
            })
        };
        if self.total_timesteps == 0 {
            return bad("total_timesteps", "must be at least 1");
        }
        if self
            .max_seconds
            .is_some_and(|s| !(s.is_finite() && s > 0.0))
        {
            return bad("max_seconds", "must be a positive number of seconds");
        }
        if self.n_envs == 0 || self.n_envs > 1024 {
            return bad("n_envs", "must be in 1..=1024");
        }
        match self.algo {
            Algo::Ppo => crate::ppo::validate(&self.ppo, self.n_envs)?,
            Algo::Sac => crate::sac::validate(&self.sac, self.n_envs)?,
            Algo::Td3 => crate::td3::validate(&self.td3, self.n_envs)?,
        }
        if self.eval.freq > 0 && self.eval.episodes == 0 {
            return bad("eval.episodes", "must be at least 1 when evaluating");
        }
        let bound = self.eval.confirm_lower_bound;
        if !(bound.is_finite() && (0.0..=1.0).contains(&bound)) {
            return bad("eval.confirm_lower_bound", "must be in [0, 1]");
        }
        let [w, h] = self.eval.record_size;
        if !((16..=1920).contains(&w) && (16..=1080).contains(&h)) {
            return bad(
                "eval.record_size",
                "must be [width, height] within 16×16 and 1920×1080",
            );
        }
        self.normalize
            .validate()
            .map_err(|problem| RlError::Config {
                key: "normalize".into(),
                problem,
            })?;
        let check = |section: &str, env: &toml::Table| {
            registry::validate(&self.env_id, env).map_err(|e| match e {
                fairgrasp_env::EnvError::Config { key, problem } => RlError::Config {
                    key: format!("{section}.{key}"),
                    problem: format!("{problem} ({})", self.env_id),
                },
                other => other.into(),
            })
        };
        check("env", &self.env)?;
        if !self.eval.env.is_empty() {
            let eval_env = self.eval_env();
            check("eval.env", &eval_env)?;
            // The policy trained on one env must be able to act in the other.
            let sizes = |env: &toml::Table| -> Result<(usize, usize)> {
                let e = registry::make(&self.env_id, env)?;
                Ok((e.observation_space().dim(), e.action_space().dim()))
            };
            let (train, eval) = (sizes(&self.env)?, sizes(&eval_env)?);
            if train != eval {
                return bad(
                    "eval.env",
                    &format!(
                        "changes the (observation, action) sizes from {train:?} to {eval:?}: \
                         the policy could not act in it"
                    ),
                );
            }
        }
        Ok(())
    }

    /// The env the evaluations play: the training env with `eval.env` laid over it.
    pub fn eval_env(&self) -> toml::Table {
        let mut env = self.env.clone();
        fairgrasp_env::config::overlay(&mut env, &self.eval.env);
        env
    }
}

/// Progress reported to the caller (for a progress bar).
#[derive(Clone, Debug, Default)]
pub struct Progress {
    pub num_timesteps: u64,
    pub total_timesteps: u64,
    /// Environment steps per second of wall time, updates included.
    pub fps: f64,
    pub ep_rew_mean: Option<f32>,
    pub rollout_success_rate: Option<f32>,
    /// For each of the task's extras, the mean over recent episodes of its largest value in
    /// the episode (`grasped`: the share of episodes with a grasp; `lift`: the mean peak lift).
    pub rollout_max_extras: NamedValues,
    pub last_eval: Option<EvalResult>,
    /// Evaluations run so far (in this session).
    pub eval_count: usize,
    pub best_success_rate: Option<f32>,
}

/// Summary of a finished run (also written to `summary.json` in the run directory).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct TrainSummary {
    pub algo: String,
    pub num_timesteps: u64,
    /// Wall time of the whole run, across resumes.
    pub seconds: f64,
    /// Environment steps per second of this session, updates and evaluations included.
    pub fps: f64,
    /// Peak resident memory of the process (MiB), where the system reports it.
    pub peak_memory_mib: Option<f64>,
    pub best: Option<EvalResult>,
    pub run_dir: PathBuf,
    /// The step the run resumed from, if it did.
    pub resumed_from: Option<u64>,
    /// Whether the run stopped early at the evaluation success threshold.
    pub reached_threshold: bool,
    /// Whether the caller stopped the run from its progress callback ([`train_until`]: Ctrl-C
    /// in Python, a Ray Tune scheduler).
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

/// The driver's own state, saved with each checkpoint (`trainer_state.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
struct TrainerState {
    format_version: u32,
    num_timesteps: u64,
    next_eval: u64,
    next_checkpoint: u64,
    best: Option<EvalResult>,
    /// Wall time spent before this checkpoint (s).
    elapsed_seconds: f64,
    recent_episodes: Vec<EpisodeStats>,
    /// The full normalisation state (JSON of [`VecNormalizeState`]).
    normalization: String,
}

const TRAINER_STATE: &str = "trainer_state.json";
const TRAINING_STATE: &str = "training_state.safetensors";

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
    config.validate()?;
    let io = |e: std::io::Error| RlError::Other(format!("{}: {e}", run_dir.display()));
    std::fs::create_dir_all(run_dir).map_err(io)?;
    let effective = toml::to_string(config).map_err(|e| RlError::Other(e.to_string()))?;
    atomic::write(&run_dir.join("config.toml"), effective.as_bytes()).map_err(io)?;
    dispatch(config, run_dir, None, on_progress)
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
    let config_path = run_dir.join("config.toml");
    let text = std::fs::read_to_string(&config_path).map_err(|e| {
        RlError::Model(format!(
            "cannot resume {}: {}: {e}",
            run_dir.display(),
            config_path.display()
        ))
    })?;
    let config = TrainConfig::from_toml_str(&text, overrides)?;
    let checkpoint = checkpoints(run_dir)
        .pop()
        .map(|(_, path)| path)
        .ok_or_else(|| {
            RlError::Model(format!(
                "cannot resume {}: no complete checkpoint in {}",
                run_dir.display(),
                run_dir.join("checkpoints").display()
            ))
        })?;
    if !overrides.is_empty() {
        let effective = toml::to_string(&config).map_err(|e| RlError::Other(e.to_string()))?;
        atomic::write(&config_path, effective.as_bytes())
            .map_err(|e| RlError::Other(format!("{}: {e}", config_path.display())))?;
    }
    dispatch(&config, run_dir, Some(checkpoint), on_progress)
}

/// The checkpoint directories of a run, oldest first (incomplete ones are skipped).
pub fn checkpoints(run_dir: &Path) -> Vec<(u64, PathBuf)> {
    let mut found: Vec<(u64, PathBuf)> = std::fs::read_dir(run_dir.join("checkpoints"))
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|entry| {
            let name = entry.file_name().into_string().ok()?;
            let step = name.strip_prefix("step_")?.parse().ok()?;
            let path = entry.path();
            path.join(TRAINER_STATE).is_file().then_some((step, path))
        })
        .collect();
    found.sort();
    found
}

fn dispatch(
    config: &TrainConfig,
    run_dir: &Path,
    checkpoint: Option<PathBuf>,
    on_progress: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<TrainSummary> {
    let envs = (0..config.n_envs)
        .map(|_| registry::make(&config.env_id, &config.env).and_then(RescaleAction::new))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    let venv = VecNormalize::new(VecEnv::new(envs, config.threads)?, config.normalize.clone())?;
    let (obs_dim, act_dim) = (venv.obs_dim(), venv.act_dim());
    match config.algo {
        Algo::Ppo => {
            let mut ppo = Ppo::with_privileged(
                config.ppo.clone(),
                obs_dim,
                act_dim,
                venv.privileged_dim(),
                config.n_envs,
                config.seed,
            )?;
            // The env threads idle during the update; its two heads use them.
            ppo.set_update_threads(config.threads)?;
            run(config, run_dir, ppo, venv, checkpoint, on_progress)
        }
        Algo::Sac => {
            let sac = Sac::new(
                config.sac.clone(),
                obs_dim,
                act_dim,
                config.n_envs,
                config.seed,
            )?;
            run(config, run_dir, sac, venv, checkpoint, on_progress)
        }
        Algo::Td3 => {
            let td3 = Td3::new(
                config.td3.clone(),
                obs_dim,
                act_dim,
                config.n_envs,
                config.seed,
            )?;
            run(config, run_dir, td3, venv, checkpoint, on_progress)
        }
    }
}

/// The training loop shared by every algorithm.
fn run<A: Algorithm>(
    config: &TrainConfig,
    run_dir: &Path,
    mut algo: A,
    mut venv: VecNormalize<VecEnv<RescaleAction<Box<dyn Env>>>>,
    checkpoint: Option<PathBuf>,
    mut on_progress: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<TrainSummary> {
    let io = |e: std::io::Error| RlError::Other(format!("{}: {e}", run_dir.display()));
    let (obs_dim, act_dim) = (venv.obs_dim(), venv.act_dim());
    let mut recent: VecDeque<EpisodeStats> = VecDeque::with_capacity(100);
    let mut best: Option<EvalResult> = None;
    let mut next_eval = config.eval.freq;
    let mut next_checkpoint = config.checkpoint_freq;
    let mut elapsed_before = 0.0;
    let mut resumed_from = None;
    let mut reached_threshold = false;
    let mut stopped = false;
    let mut csv = CsvLogger::open(run_dir).map_err(io)?;

    if let Some(dir) = &checkpoint {
        let state = read_trainer_state(dir)?;
        let meta = ModelMeta::load(dir)?;
        meta.check_compatible(algo.name(), obs_dim, act_dim)?;
        algo.load_weights(&load_tensors(&dir.join("model.safetensors"))?)?;
        algo.load_training_state(&load_tensors(&dir.join(TRAINING_STATE))?)?;
        algo.set_num_timesteps(state.num_timesteps);
        let normalization = VecNormalizeState::from_json(&state.normalization)
            .map_err(|p| RlError::Model(format!("{}: {p}", dir.join(TRAINER_STATE).display())))?;
        venv.set_state(normalization)?;
        recent.extend(state.recent_episodes);
        best = state.best;
        next_eval = state.next_eval;
        next_checkpoint = state.next_checkpoint;
        elapsed_before = state.elapsed_seconds;
        resumed_from = Some(state.num_timesteps);
        // Rows logged after the checkpoint belong to the interrupted attempt.
        csv.truncate_after("time/total_timesteps", state.num_timesteps as f64)
            .map_err(io)?;
        // Fresh episodes, on streams that depend on where the run stands.
        let reseed = config
            .seed
            .wrapping_add(state.num_timesteps.wrapping_mul(0x9e37_79b9_7f4a_7c15));
        venv.reset(Some(reseed))?;
    } else {
        venv.reset(Some(config.seed))?;
    }
    let mut tb = TensorBoardWriter::create(&run_dir.join("tb")).map_err(io)?;

    let env_json = serde_json::to_value(&config.env).map_err(|e| RlError::Other(e.to_string()))?;
    let privileged_dim = match config.algo == Algo::Ppo && config.ppo.privileged_critic {
        true => venv.privileged_dim(),
        false => 0,
    };
    let meta = |algo: &A, venv: &VecNormalize<_>| ModelMeta {
        format_version: crate::model::FORMAT_VERSION,
        algo: algo.name().into(),
        obs_dim,
        act_dim,
        ppo: (config.algo == Algo::Ppo).then(|| config.ppo.clone()),
        sac: (config.algo == Algo::Sac).then(|| config.sac.clone()),
        td3: (config.algo == Algo::Td3).then(|| config.td3.clone()),
        env_id: config.env_id.clone(),
        env: env_json.clone(),
        normalization: config.normalize.norm_obs.then(|| venv.state().to_json()),
        num_timesteps: algo.num_timesteps(),
        train_seed: config.seed,
        n_envs: config.n_envs,
        privileged_dim,
    };

    let eval_env = config.eval_env();
    let started = Instant::now();
    let start_steps = algo.num_timesteps();
    let mut progress = Progress {
        total_timesteps: config.total_timesteps,
        best_success_rate: best.as_ref().map(|b| b.success_rate),
        ..Progress::default()
    };
    // Off-policy learners iterate once per vector step: log those every 1,000 steps.
    let log_every = match config.algo {
        Algo::Ppo => 0,
        Algo::Sac | Algo::Td3 => 1000,
    };
    let mut last_log = algo.num_timesteps();
    while algo.num_timesteps() < config.total_timesteps {
        let remaining = 1.0 - algo.num_timesteps() as f64 / config.total_timesteps as f64;
        let mut on_step = |step: &fairgrasp_env::VecStep<'_>| {
            for end in step.episode_ends.iter().flatten() {
                if recent.len() == 100 {
                    recent.pop_front();
                }
                recent.push_back(end.episode.clone());
            }
        };
        let train_scalars = algo.learn_iteration(&mut venv, remaining, &mut on_step)?;
        let steps = algo.num_timesteps();
        let session = started.elapsed().as_secs_f64();
        progress.num_timesteps = steps;
        progress.fps = (steps - start_steps) as f64 / session.max(1e-9);
        if !recent.is_empty() {
            let n = recent.len() as f32;
            let mean = |f: fn(&EpisodeStats) -> f32| recent.iter().map(f).sum::<f32>() / n;
            progress.ep_rew_mean = Some(mean(|e| e.episode_return as f32));
            progress.rollout_success_rate = Some(mean(|e| e.success as u8 as f32));
            let mut sums = NamedValues::new();
            for e in &recent {
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
        if !train_scalars.is_empty() && steps - last_log >= log_every {
            last_log = steps;
            log_iteration(
                &mut tb,
                &mut csv,
                &progress,
                elapsed_before + session,
                &train_scalars,
            )
            .map_err(io)?;
        }

        let mut stop = false;
        if config.eval.freq > 0 && steps >= next_eval {
            next_eval += config.eval.freq;
            // Acts exactly as the saved model will (`fairgrasp eval`, deployment), one policy
            // per thread: the episodes run on the env threads, idle during evaluation.
            let (model_meta, weights) = (meta(&algo, &venv), algo.weights()?);
            let make_actor = || -> Result<Actor<'static>> {
                let mut policy = Policy::from_parts(model_meta.clone(), &weights)?;
                Ok(Box::new(move |obs: &[f32]| policy.act(obs, true)))
            };
            let result = evaluate_parallel(
                &make_actor,
                &config.env_id,
                &eval_env,
                config.eval.episodes,
                EVAL_SEED_BASE,
                config.threads,
            )?;
            let mut scalars: Vec<(String, f32)> = vec![
                ("eval/success_rate".into(), result.success_rate),
                ("eval/mean_reward".into(), result.mean_return),
                ("eval/mean_ep_length".into(), result.mean_length),
            ];
            scalars.extend(
                result
                    .final_extras
                    .iter()
                    .map(|(name, v)| (format!("eval/{name}"), v)),
            );
            if config.eval.record {
                let mut actor = make_actor()?;
                let gif = record_episode(
                    &mut actor,
                    &config.env_id,
                    &eval_env,
                    EVAL_SEED_BASE,
                    config.eval.record_size,
                )?;
                let path = run_dir.join("videos").join(format!("eval_{steps}.gif"));
                std::fs::create_dir_all(run_dir.join("videos")).map_err(io)?;
                atomic::write(&path, &gif).map_err(io)?;
            }
            tb.add_scalars(steps, &scalars).map_err(io)?;
            let mut row: Vec<(&str, f64)> = scalars
                .iter()
                .map(|(k, v)| (k.as_str(), *v as f64))
                .collect();
            row.push(("time/total_timesteps", steps as f64));
            row.push((
                "time/time_elapsed",
                elapsed_before + started.elapsed().as_secs_f64(),
            ));
            csv.write_row(&row).map_err(io)?;
            let reached = (config.eval.success_threshold).is_some_and(|t| result.success_rate >= t);
            // The confirmation: more episodes on validation seeds, the stop on their lower bound.
            let confirmed = if reached && config.eval.confirm_episodes > 0 {
                let confirmation = evaluate_parallel(
                    &make_actor,
                    &config.env_id,
                    &eval_env,
                    config.eval.confirm_episodes,
                    VALIDATION_SEED_BASE,
                    config.threads,
                )?;
                let successes = (confirmation.success_rate * confirmation.episodes as f32).round();
                let bound = wilson_lower_bound(successes as u32, confirmation.episodes);
                tb.add_scalars(
                    steps,
                    &[
                        ("eval/confirmed_success_rate", confirmation.success_rate),
                        ("eval/confirmed_lower_bound", bound as f32),
                    ],
                )
                .map_err(io)?;
                Some((confirmation, bound))
            } else {
                None
            };
            // A confirmed result outranks an unconfirmed one; among equals, success then return.
            let rank = |r: &EvalResult| (r.confirmed, r.success_rate, r.mean_return);
            let candidate = match &confirmed {
                Some((c, _)) => EvalResult {
                    confirmed: true,
                    ..c.clone()
                },
                None => result.clone(),
            };
            let better = best.as_ref().is_none_or(|b| rank(&candidate) > rank(b));
            if better {
                save_model(&run_dir.join("best"), &algo.weights()?, &meta(&algo, &venv))?;
                best = Some(candidate);
            }
            progress.best_success_rate = best.as_ref().map(|b| b.success_rate);
            progress.last_eval = Some(result.clone());
            progress.eval_count += 1;
            stop = match &confirmed {
                Some((_, bound)) => *bound >= config.eval.confirm_lower_bound as f64,
                None => reached && config.eval.confirm_episodes == 0,
            };
        }
        if config.checkpoint_freq > 0 && steps >= next_checkpoint {
            next_checkpoint += config.checkpoint_freq;
            let state = TrainerState {
                format_version: 1,
                num_timesteps: steps,
                next_eval,
                next_checkpoint,
                best: best.clone(),
                elapsed_seconds: elapsed_before + started.elapsed().as_secs_f64(),
                recent_episodes: recent.iter().cloned().collect(),
                normalization: venv.state().to_json(),
            };
            write_checkpoint(run_dir, &algo, &meta(&algo, &venv), &state)?;
        }
        tb.flush().map_err(io)?;
        if on_progress(&progress).is_break() {
            stopped = true;
            break;
        }
        if stop {
            reached_threshold = true;
            break;
        }
        if config
            .max_seconds
            .is_some_and(|limit| elapsed_before + started.elapsed().as_secs_f64() >= limit)
        {
            break;
        }
    }
    save_model(
        &run_dir.join("final"),
        &algo.weights()?,
        &meta(&algo, &venv),
    )?;
    tb.flush().map_err(io)?;
    let session = started.elapsed().as_secs_f64();
    let summary = TrainSummary {
        algo: algo.name().into(),
        num_timesteps: algo.num_timesteps(),
        seconds: elapsed_before + session,
        fps: (algo.num_timesteps() - start_steps) as f64 / session.max(1e-9),
        peak_memory_mib: peak_memory_mib(),
        best,
        run_dir: run_dir.to_path_buf(),
        resumed_from,
        reached_threshold,
        stopped,
    };
    let json = serde_json::to_string_pretty(&summary).map_err(|e| RlError::Other(e.to_string()))?;
    atomic::write(&run_dir.join("summary.json"), json.as_bytes()).map_err(io)?;
    Ok(summary)
}

/// Writes `checkpoints/step_<N>/` through a staging directory, so an interrupted write never
/// leaves a checkpoint that [`resume`] would pick.
fn write_checkpoint<A: Algorithm>(
    run_dir: &Path,
    algo: &A,
    meta: &ModelMeta,
    state: &TrainerState,
) -> Result<()> {
    let dir = run_dir
        .join("checkpoints")
        .join(format!("step_{}", state.num_timesteps));
    let staging = run_dir
        .join("checkpoints")
        .join(format!(".step_{}.partial", state.num_timesteps));
    let _ = std::fs::remove_dir_all(&staging);
    write_model_files(&staging, &algo.weights()?, meta)?;
    let training: TensorMap = algo.training_state()?;
    save_tensors(&staging.join(TRAINING_STATE), &training)?;
    let json = serde_json::to_string(state).map_err(|e| RlError::Other(e.to_string()))?;
    atomic::write(&staging.join(TRAINER_STATE), json.as_bytes())
        .map_err(|e| RlError::Other(format!("{}: {e}", staging.display())))?;
    replace_dir(&staging, &dir)
}

fn read_trainer_state(dir: &Path) -> Result<TrainerState> {
    let path = dir.join(TRAINER_STATE);
    let text = std::fs::read_to_string(&path)
        .map_err(|e| RlError::Model(format!("{}: {e}", path.display())))?;
    let state: TrainerState = serde_json::from_str(&text).map_err(|e| {
        RlError::Model(format!(
            "{}: not a fairgrasp trainer state: {e}",
            path.display()
        ))
    })?;
    if state.format_version != 1 {
        return Err(RlError::Model(format!(
            "{}: format version {} is not supported (this build reads 1)",
            path.display(),
            state.format_version
        )));
    }
    Ok(state)
}

fn log_iteration(
    tb: &mut TensorBoardWriter,
    csv: &mut CsvLogger,
    p: &Progress,
    elapsed: f64,
    train_scalars: &[(&'static str, f32)],
) -> std::io::Result<()> {
    let mut scalars: Vec<(String, f32)> = train_scalars
        .iter()
        .map(|(k, v)| (k.to_string(), *v))
        .collect();
    scalars.push(("time/fps".into(), p.fps as f32));
    scalars.push(("time/time_elapsed".into(), elapsed as f32));
    if let Some(r) = p.ep_rew_mean {
        scalars.push(("rollout/ep_rew_mean".into(), r));
    }
    if let Some(r) = p.rollout_success_rate {
        scalars.push(("rollout/success_rate".into(), r));
    }
    for (name, value) in p.rollout_max_extras.iter() {
        scalars.push((format!("rollout/max_{name}"), value));
    }
    tb.add_scalars(p.num_timesteps, &scalars)?;
    let mut row: Vec<(&str, f64)> = scalars
        .iter()
        .map(|(k, v)| (k.as_str(), *v as f64))
        .collect();
    row.push(("time/total_timesteps", p.num_timesteps as f64));
    csv.write_row(&row)
}
