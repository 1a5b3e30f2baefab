//! The training run: environments, PPO, evaluation with best-model saving, checkpoints,
//! TensorBoard and CSV logs — what SB3's `learn()` with `EvalCallback` and
//! `CheckpointCallback` gives, in one driver.
//!
//! A run directory holds `config.toml` (the effective configuration), `tb/` (TensorBoard event
//! files), `progress.csv`, `best/` (the best model by evaluation success rate, then return) and
//! `checkpoints/step_<N>/`.

use crate::logger::{CsvLogger, TensorBoardWriter};
use crate::ppo::{Ppo, PpoConfig, Result, RlError, UpdateStats};
use crate::save_util::write_atomic;
use candle_core::Tensor;
use fairgrasp_env::wrappers::{RescaleAction, VecNormalize, VecNormalizeConfig, VecNormalizeState};
use fairgrasp_env::{Env, EnvConfig, GraspEnv, VecEnv, VectorEnv};
use rand::SeedableRng;
use serde::{Deserialize, Serialize};
use std::collections::{HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Evaluation during training (like SB3's `EvalCallback`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvalConfig {
    /// Evaluate every this many environment steps (0: never).
    pub freq: u64,
    pub episodes: u32,
    /// Stop training once the evaluation success rate reaches this.
    pub success_threshold: Option<f32>,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            freq: 50_000,
            episodes: 20,
            success_threshold: None,
        }
    }
}

/// Everything that defines a training run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    pub total_timesteps: u64,
    pub seed: u64,
    /// Parallel environments.
    pub n_envs: usize,
    /// Threads stepping them.
    pub threads: usize,
    /// Save a checkpoint every this many environment steps (0: never).
    pub checkpoint_freq: u64,
    pub normalize: VecNormalizeConfig,
    pub eval: EvalConfig,
    pub ppo: PpoConfig,
    pub env: EnvConfig,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            total_timesteps: 2_000_000,
            seed: 42,
            n_envs: 4,
            threads: 2,
            checkpoint_freq: 200_000,
            normalize: VecNormalizeConfig::default(),
            eval: EvalConfig::default(),
            ppo: PpoConfig::default(),
            env: EnvConfig::default(),
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
        if self.n_envs == 0 || self.n_envs > 1024 {
            return bad("n_envs", "must be in 1..=1024");
        }
        crate::ppo::validate(&self.ppo, self.n_envs)?;
        if self.eval.freq > 0 && self.eval.episodes == 0 {
            return bad("eval.episodes", "must be at least 1 when evaluating");
        }
        self.normalize
            .validate()
            .map_err(|problem| RlError::Config {
                key: "normalize".into(),
                problem,
            })?;
        self.env.validate()?;
        Ok(())
    }
}

/// What a saved model needs besides its weights (stored as `model.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ModelMeta {
    pub format_version: u32,
    pub algo: String,
    pub obs_dim: usize,
    pub act_dim: usize,
    pub ppo: PpoConfig,
    pub env: EnvConfig,
    /// Observation normalisation statistics (JSON of `VecNormalizeState`), if used.
    pub normalization: Option<String>,
    pub num_timesteps: u64,
}

/// Saves a model directory: `model.safetensors` (weights) and `model.json`, each atomically.
pub fn save_model(dir: &Path, ppo: &Ppo, meta: &ModelMeta) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| RlError::Other(format!("{}: {e}", dir.display())))?;
    let tensors: HashMap<String, Tensor> = ppo
        .policy
        .varmap
        .data()
        .lock()
        .expect("varmap lock")
        .iter()
        .map(|(k, v)| (k.clone(), v.as_tensor().clone()))
        .collect();
    save_tensors(&dir.join("model.safetensors"), &tensors)?;
    let json = serde_json::to_string_pretty(meta).map_err(|e| RlError::Other(e.to_string()))?;
    write_atomic(&dir.join("model.json"), json.as_bytes())
        .map_err(|e| RlError::Other(format!("{}: {e}", dir.display())))
}

/// Writes tensors as safetensors through a temporary file, so a crash never leaves a torn file.
pub fn save_tensors(path: &Path, tensors: &HashMap<String, Tensor>) -> Result<()> {
    let tmp = path.with_extension("safetensors.tmp");
    candle_core::safetensors::save(tensors, &tmp)?;
    std::fs::rename(&tmp, path).map_err(|e| RlError::Other(format!("{}: {e}", path.display())))
}

/// Result of an evaluation.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EvalResult {
    pub success_rate: f32,
    pub mean_return: f32,
    pub mean_length: f32,
}

/// Runs the deterministic policy on fresh environments with seeds `seed, seed+1, …`.
pub fn evaluate(
    ppo: &Ppo,
    env_config: &EnvConfig,
    normalization: Option<&VecNormalizeState>,
    episodes: u32,
    seed: u64,
) -> Result<EvalResult> {
    let mut env = RescaleAction::new(GraspEnv::new(env_config.clone())?)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (mut successes, mut total_return, mut total_length) = (0u32, 0.0f32, 0u64);
    for e in 0..episodes as u64 {
        let (mut obs, _) = env.reset(Some(seed + e))?;
        loop {
            let input = match normalization {
                Some(n) => n.normalize_obs(&obs)?,
                None => obs.clone(),
            };
            let mut action = ppo.policy.act(&input, true, &mut rng)?.actions;
            env.action_space().clip(&mut action);
            let step = env.step(&action)?;
            total_return += step.reward;
            obs = step.obs;
            if step.terminated || step.truncated {
                successes += step.info.success as u32;
                total_length += step.info.elapsed_steps as u64;
                break;
            }
        }
    }
    let n = episodes.max(1) as f32;
    Ok(EvalResult {
        success_rate: successes as f32 / n,
        mean_return: total_return / n,
        mean_length: total_length as f32 / n,
    })
}

/// Progress reported to the caller (for a progress bar).
#[derive(Clone, Debug, Default)]
pub struct Progress {
    pub num_timesteps: u64,
    pub total_timesteps: u64,
    pub fps: f64,
    pub ep_rew_mean: Option<f32>,
    pub rollout_success_rate: Option<f32>,
    pub last_eval: Option<EvalResult>,
    pub best_success_rate: Option<f32>,
}

/// Summary of a finished run.
#[derive(Clone, Debug, Default)]
pub struct TrainSummary {
    pub num_timesteps: u64,
    pub seconds: f64,
    pub best: Option<EvalResult>,
    pub run_dir: PathBuf,
}

/// Trains PPO on the grasp task as configured, writing everything to `run_dir`.
pub fn train_ppo(
    config: &TrainConfig,
    run_dir: &Path,
    mut on_progress: impl FnMut(&Progress),
) -> Result<TrainSummary> {
    config.validate()?;
    let io = |e: std::io::Error| RlError::Other(format!("{}: {e}", run_dir.display()));
    std::fs::create_dir_all(run_dir).map_err(io)?;
    let effective = toml::to_string(config).map_err(|e| RlError::Other(e.to_string()))?;
    write_atomic(&run_dir.join("config.toml"), effective.as_bytes()).map_err(io)?;
    let mut tb = TensorBoardWriter::create(&run_dir.join("tb")).map_err(io)?;
    let mut csv = CsvLogger::open(run_dir).map_err(io)?;

    let envs = (0..config.n_envs)
        .map(|_| GraspEnv::new(config.env.clone()).and_then(RescaleAction::new))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    let mut venv = VecNormalize::new(VecEnv::new(envs, config.threads)?, config.normalize.clone())?;
    venv.reset(Some(config.seed))?;
    let (obs_dim, act_dim) = (venv.obs_dim(), venv.act_dim());
    let mut ppo = Ppo::new(
        config.ppo.clone(),
        obs_dim,
        act_dim,
        config.n_envs,
        config.seed,
    )?;
    let meta = |ppo: &Ppo, venv: &VecNormalize<_>| ModelMeta {
        format_version: 1,
        algo: "ppo".into(),
        obs_dim,
        act_dim,
        ppo: config.ppo.clone(),
        env: config.env.clone(),
        normalization: config.normalize.norm_obs.then(|| venv.state().to_json()),
        num_timesteps: ppo.num_timesteps,
    };

    let started = Instant::now();
    let mut episode_starts = vec![true; config.n_envs];
    let mut recent: VecDeque<(f64, bool)> = VecDeque::with_capacity(100);
    let mut progress = Progress {
        total_timesteps: config.total_timesteps,
        ..Progress::default()
    };
    let mut best: Option<EvalResult> = None;
    let mut next_eval = config.eval.freq;
    let mut next_checkpoint = config.checkpoint_freq;
    while ppo.num_timesteps < config.total_timesteps {
        ppo.collect_rollout(&mut venv, &mut episode_starts, |step| {
            for end in step.episode_ends.iter().flatten() {
                if recent.len() == 100 {
                    recent.pop_front();
                }
                recent.push_back((end.episode.episode_return, end.episode.success));
            }
        })?;
        let remaining = 1.0 - ppo.num_timesteps as f64 / config.total_timesteps as f64;
        let stats = ppo.update(remaining)?;
        let elapsed = started.elapsed().as_secs_f64();
        progress.num_timesteps = ppo.num_timesteps;
        progress.fps = ppo.num_timesteps as f64 / elapsed.max(1e-9);
        if !recent.is_empty() {
            let n = recent.len() as f32;
            progress.ep_rew_mean = Some(recent.iter().map(|r| r.0 as f32).sum::<f32>() / n);
            progress.rollout_success_rate = Some(recent.iter().filter(|r| r.1).count() as f32 / n);
        }
        log_update(&mut tb, &mut csv, &progress, &stats).map_err(io)?;

        if config.eval.freq > 0 && ppo.num_timesteps >= next_eval {
            next_eval += config.eval.freq;
            let norm = config.normalize.norm_obs.then(|| venv.state());
            let result = evaluate(&ppo, &config.env, norm, config.eval.episodes, 1_000_000)?;
            let scalars = [
                ("eval/success_rate", result.success_rate),
                ("eval/mean_reward", result.mean_return),
                ("eval/mean_ep_length", result.mean_length),
            ];
            tb.add_scalars(ppo.num_timesteps, &scalars).map_err(io)?;
            let better = best.as_ref().is_none_or(|b| {
                (result.success_rate, result.mean_return) > (b.success_rate, b.mean_return)
            });
            if better {
                save_model(&run_dir.join("best"), &ppo, &meta(&ppo, &venv))?;
                best = Some(result.clone());
            }
            progress.best_success_rate = best.as_ref().map(|b| b.success_rate);
            progress.last_eval = Some(result.clone());
            if let Some(threshold) = config.eval.success_threshold
                && result.success_rate >= threshold
            {
                on_progress(&progress);
                break;
            }
        }
        if config.checkpoint_freq > 0 && ppo.num_timesteps >= next_checkpoint {
            next_checkpoint += config.checkpoint_freq;
            let dir = run_dir
                .join("checkpoints")
                .join(format!("step_{}", ppo.num_timesteps));
            save_model(&dir, &ppo, &meta(&ppo, &venv))?;
            save_tensors(&dir.join("optimizer.safetensors"), &ppo.optimizer.state()?)?;
        }
        tb.flush().map_err(io)?;
        on_progress(&progress);
    }
    save_model(&run_dir.join("final"), &ppo, &meta(&ppo, &venv))?;
    tb.flush().map_err(io)?;
    Ok(TrainSummary {
        num_timesteps: ppo.num_timesteps,
        seconds: started.elapsed().as_secs_f64(),
        best,
        run_dir: run_dir.to_path_buf(),
    })
}

fn log_update(
    tb: &mut TensorBoardWriter,
    csv: &mut CsvLogger,
    p: &Progress,
    s: &UpdateStats,
) -> std::io::Result<()> {
    let mut scalars = vec![
        ("train/policy_gradient_loss", s.policy_loss),
        ("train/value_loss", s.value_loss),
        ("train/entropy_loss", -s.entropy),
        ("train/approx_kl", s.approx_kl),
        ("train/clip_fraction", s.clip_fraction),
        ("train/explained_variance", s.explained_variance),
        ("train/learning_rate", s.learning_rate as f32),
        ("train/std", s.std),
        ("train/grad_norm", s.grad_norm),
        ("time/fps", p.fps as f32),
    ];
    if let Some(r) = p.ep_rew_mean {
        scalars.push(("rollout/ep_rew_mean", r));
    }
    if let Some(r) = p.rollout_success_rate {
        scalars.push(("rollout/success_rate", r));
    }
    tb.add_scalars(p.num_timesteps, &scalars)?;
    let mut row: Vec<(&str, f64)> = scalars.iter().map(|(k, v)| (*k, *v as f64)).collect();
    row.push(("time/total_timesteps", p.num_timesteps as f64));
    csv.write_row(&row)
}
