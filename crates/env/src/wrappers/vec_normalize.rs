//! [`VecNormalize`]: running normalisation of observations and rewards (SB3's `VecNormalize`).

use crate::core::Info;
use crate::error::{EnvError, Result};
use crate::running_stats::RunningMeanStd;
use crate::spaces::{BoxSpace, ImageSpace};
use crate::vector::{EpisodeEnd, VecStep, VectorEnv};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The `format` tag of a statistics file.
const FORMAT: &str = "fairgrasp.vec_normalize";
/// The version of the statistics file layout this build writes and reads.
const VERSION: u32 = 1;

/// The settings of [`VecNormalize`], with SB3's defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VecNormalizeConfig {
    /// Normalise observations: `clip((obs - mean) / sqrt(var + epsilon), ±clip_obs)`.
    pub norm_obs: bool,
    /// Normalise rewards: `clip(reward / sqrt(var(discounted return) + epsilon), ±clip_reward)`.
    pub norm_reward: bool,
    /// Bound of normalised observations (SB3: 10).
    pub clip_obs: f32,
    /// Bound of normalised rewards (SB3: 10).
    pub clip_reward: f32,
    /// Discount of the return whose running variance scales the rewards; use the agent's.
    pub gamma: f64,
    /// Added to the variances before the square root (SB3: 1e-8).
    pub epsilon: f64,
}

impl Default for VecNormalizeConfig {
    fn default() -> Self {
        Self {
            norm_obs: true,
            norm_reward: true,
            clip_obs: 10.0,
            clip_reward: 10.0,
            gamma: 0.99,
            epsilon: 1e-8,
        }
    }
}

impl VecNormalizeConfig {
    /// Checks every setting; the message names the first bad one.
    pub fn validate(&self) -> std::result::Result<(), String> {
        for (key, v) in [
            ("clip_obs", self.clip_obs),
            ("clip_reward", self.clip_reward),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{key} must be a positive number, got {v}"));
            }
        }
        if !(0.0..=1.0).contains(&self.gamma) {
            return Err(format!("gamma must lie in [0, 1], got {}", self.gamma));
        }
        if !(self.epsilon.is_finite() && self.epsilon > 0.0) {
            return Err(format!(
                "epsilon must be a positive number, got {}",
                self.epsilon
            ));
        }
        Ok(())
    }
}

/// What [`VecNormalize`] saves and loads: its settings and the running statistics of the
/// observations and of the discounted return. On its own, it normalises observations for
/// evaluation or deployment without a vector environment:
///
/// ```no_run
/// # fn main() -> fairgrasp_env::Result<()> {
/// use fairgrasp_env::VecNormalizeState;
/// let stats = VecNormalizeState::load("runs/ppo/vec_normalize.json".as_ref())?;
/// let policy_input = stats.normalize_obs(&[0.0; 40])?;
/// # Ok(())
/// # }
/// ```
///
/// # File format
///
/// JSON: `{"format": "fairgrasp.vec_normalize", "version": 1, "config": {…},
/// "obs_rms": {"mean": […], "var": […], "count": …}, "ret_rms": {…}}`. The statistics are
/// written as decimal strings that read back bit-exactly (see [`RunningMeanStd`]).
#[derive(Clone, Debug, PartialEq)]
pub struct VecNormalizeState {
    /// What is normalised, the clip bounds, the discount and epsilon.
    pub config: VecNormalizeConfig,
    /// Statistics of the observations (`obs_dim` components).
    pub obs_rms: RunningMeanStd,
    /// Statistics of the discounted return (one component).
    pub ret_rms: RunningMeanStd,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct StatsFile {
    format: String,
    version: u32,
    config: VecNormalizeConfig,
    obs_rms: RunningMeanStd,
    ret_rms: RunningMeanStd,
}

impl VecNormalizeState {
    /// Fresh statistics (SB3's: mean 0, variance 1, pseudo-count 1e-4) for `obs_dim`-value
    /// observations.
    pub fn new(obs_dim: usize, config: VecNormalizeConfig) -> Result<Self> {
        config
            .validate()
            .map_err(|p| EnvError::Usage(format!("VecNormalize: {p}")))?;
        Ok(Self {
            config,
            obs_rms: RunningMeanStd::new(obs_dim),
            ret_rms: RunningMeanStd::new(1),
        })
    }

    /// Values per observation.
    pub fn obs_dim(&self) -> usize {
        self.obs_rms.dim()
    }

    /// Checks the settings and statistics; the message names the first problem.
    pub fn validate(&self) -> std::result::Result<(), String> {
        self.config.validate().map_err(|p| format!("config: {p}"))?;
        self.obs_rms
            .validate()
            .map_err(|p| format!("obs_rms: {p}"))?;
        self.ret_rms
            .validate()
            .map_err(|p| format!("ret_rms: {p}"))?;
        if self.ret_rms.dim() != 1 {
            return Err(format!(
                "ret_rms must have one component, it has {}",
                self.ret_rms.dim()
            ));
        }
        Ok(())
    }

    /// Normalises one observation, or several stored row-major (SB3's `normalize_obs`);
    /// unchanged when `config.norm_obs` is off. Errors when `obs` is not a whole number of
    /// observations.
    pub fn normalize_obs(&self, obs: &[f32]) -> Result<Vec<f32>> {
        self.check_rows(obs)?;
        let mut out = vec![0.0; obs.len()];
        self.normalize_obs_into(obs, &mut out);
        Ok(out)
    }

    /// The inverse of [`Self::normalize_obs`] (exact up to rounding for unclipped values).
    pub fn unnormalize_obs(&self, obs: &[f32]) -> Result<Vec<f32>> {
        self.check_rows(obs)?;
        if !self.config.norm_obs {
            return Ok(obs.to_vec());
        }
        let eps = self.config.epsilon;
        let (mean, var) = (self.obs_rms.mean(), self.obs_rms.var());
        Ok(obs
            .chunks_exact(self.obs_dim().max(1))
            .flat_map(|row| {
                row.iter()
                    .zip(mean.iter().zip(var))
                    .map(move |(&x, (&m, &v))| (x as f64 * (v + eps).sqrt() + m) as f32)
            })
            .collect())
    }

    /// Scales a reward by the running standard deviation of the discounted return and clips it
    /// (SB3's `normalize_reward`); unchanged when `config.norm_reward` is off.
    pub fn normalize_reward(&self, reward: f32) -> f32 {
        if !self.config.norm_reward {
            return reward;
        }
        let scale = (self.ret_rms.var()[0] + self.config.epsilon).sqrt();
        let clip = self.config.clip_reward as f64;
        (reward as f64 / scale).clamp(-clip, clip) as f32
    }

    /// The inverse of [`Self::normalize_reward`] for unclipped values.
    pub fn unnormalize_reward(&self, reward: f32) -> f32 {
        if !self.config.norm_reward {
            return reward;
        }
        (reward as f64 * (self.ret_rms.var()[0] + self.config.epsilon).sqrt()) as f32
    }

    fn check_rows(&self, obs: &[f32]) -> Result<()> {
        let dim = self.obs_dim();
        if obs.is_empty() || dim == 0 || !obs.len().is_multiple_of(dim) {
            return Err(EnvError::Usage(format!(
                "VecNormalize: expected one or more {dim}-value observations, got {} values",
                obs.len()
            )));
        }
        Ok(())
    }

    /// Normalises whole rows of `obs` into `out` (same length).
    fn normalize_obs_into(&self, obs: &[f32], out: &mut [f32]) {
        if !self.config.norm_obs {
            out.copy_from_slice(obs);
            return;
        }
        let clip = self.config.clip_obs as f64;
        (self.obs_rms).normalize_into(obs, self.config.epsilon, clip, out);
    }

    /// The statistics file's text.
    pub fn to_json(&self) -> String {
        let file = StatsFile {
            format: FORMAT.to_string(),
            version: VERSION,
            config: self.config.clone(),
            obs_rms: self.obs_rms.clone(),
            ret_rms: self.ret_rms.clone(),
        };
        let mut text = serde_json::to_string_pretty(&file).expect("plain data serialises");
        text.push('\n');
        text
    }

    /// Parses a statistics file's text; the message says what is wrong.
    pub fn from_json(text: &str) -> std::result::Result<Self, String> {
        let file: StatsFile = serde_json::from_str(text)
            .map_err(|e| format!("not a valid VecNormalize statistics file: {e}"))?;
        if file.format != FORMAT {
            return Err(format!("format is `{}`, expected `{FORMAT}`", file.format));
        }
        if file.version != VERSION {
            return Err(format!(
                "format version {} is not supported (this build reads version {VERSION})",
                file.version
            ));
        }
        let state = Self {
            config: file.config,
            obs_rms: file.obs_rms,
            ret_rms: file.ret_rms,
        };
        state.validate()?;
        Ok(state)
    }

    /// Writes the statistics file atomically: to a temporary file in the same directory, synced,
    /// then renamed over `path`, so that a reader never sees a half-written file and a crash
    /// leaves either the old file or the new one.
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::atomic::write(path, self.to_json().as_bytes()).map_err(|e| EnvError::File {
            path: path.display().to_string(),
            problem: format!("cannot write: {e}"),
        })
    }

    /// Reads a statistics file written by [`Self::save`]. Errors name the file and the problem.
    pub fn load(path: &Path) -> Result<Self> {
        let file_error = |problem: String| EnvError::File {
            path: path.display().to_string(),
            problem,
        };
        let text = std::fs::read_to_string(path)
            .map_err(|e| file_error(format!("cannot read VecNormalize statistics: {e}")))?;
        Self::from_json(&text).map_err(file_error)
    }
}

/// Normalises the observations and rewards of a vector environment by running statistics,
/// like SB3's `VecNormalize(venv, training=True, norm_obs=True, norm_reward=True,
/// clip_obs=10.0, clip_reward=10.0, gamma=0.99, epsilon=1e-8)`:
///
/// - observations: `clip((obs - mean) / sqrt(var + epsilon), ±clip_obs)`, with the mean and
///   variance of every observation returned by `reset` and `step` (batch-merged, float64);
/// - rewards: `clip(reward / sqrt(var(R) + epsilon), ±clip_reward)`, where `R` is each
///   environment's running discounted return `R ← gamma·R + reward`, set to 0 when its episode
///   ends;
/// - terminal observations kept for automatic resets ([`VecStep::episode_ends`]) are normalised
///   with the same statistics (not added to them); episode statistics stay in raw reward units;
/// - `training = false` freezes the statistics (use it for evaluation, and after loading
///   statistics for evaluation: [`Self::load`] starts in training mode, as SB3's does);
/// - [`Self::save`] / [`Self::load`] keep the settings and statistics in a JSON file, written
///   atomically (SB3 pickles; the running returns are not saved, as in SB3).
///
/// When the wrapped environment's `step` fails, nothing here is updated: the buffers keep the
/// previous step's values until the next `reset` (or `reset_env` of the failed environment and
/// a successful step).
pub struct VecNormalize<V> {
    venv: V,
    state: VecNormalizeState,
    training: bool,
    /// Running discounted return of each environment.
    returns: Vec<f64>,
    raw_obs: Vec<f32>,
    obs: Vec<f32>,
    raw_rewards: Vec<f32>,
    rewards: Vec<f32>,
    episode_ends: Vec<Option<EpisodeEnd>>,
    raw_terminal: Vec<Option<Vec<f32>>>,
}

impl<V: VectorEnv> VecNormalize<V> {
    /// Wraps `venv` with fresh statistics, in training mode.
    pub fn new(venv: V, config: VecNormalizeConfig) -> Result<Self> {
        let state = VecNormalizeState::new(venv.obs_dim(), config)?;
        Self::from_state(venv, state)
    }

    /// Wraps `venv` with given statistics, in training mode. Errors when their dimension is
    /// not the environment's.
    pub fn from_state(venv: V, state: VecNormalizeState) -> Result<Self> {
        state
            .validate()
            .map_err(|p| EnvError::Usage(format!("VecNormalize: {p}")))?;
        check_dim(&state, &venv).map_err(EnvError::Usage)?;
        let (n, obs_dim) = (venv.num_envs(), venv.obs_dim());
        Ok(Self {
            venv,
            state,
            training: true,
            returns: vec![0.0; n],
            raw_obs: vec![0.0; n * obs_dim],
            obs: vec![0.0; n * obs_dim],
            raw_rewards: vec![0.0; n],
            rewards: vec![0.0; n],
            episode_ends: vec![None; n],
            raw_terminal: vec![None; n],
        })
    }

    /// Wraps `venv` with the settings and statistics saved at `path` (SB3's
    /// `VecNormalize.load(path, venv)`), in training mode. Errors name the file and the
    /// problem: unreadable, not a statistics file, invalid values, or statistics for
    /// observations of another size.
    pub fn load(path: &Path, venv: V) -> Result<Self> {
        let state = VecNormalizeState::load(path)?;
        check_dim(&state, &venv).map_err(|problem| EnvError::File {
            path: path.display().to_string(),
            problem,
        })?;
        Self::from_state(venv, state)
    }

    /// Saves the settings and statistics atomically (see [`VecNormalizeState::save`]).
    pub fn save(&self, path: &Path) -> Result<()> {
        self.state.save(path)
    }

    /// The settings and statistics.
    pub fn state(&self) -> &VecNormalizeState {
        &self.state
    }

    /// Replaces the settings and statistics (e.g. to sync an evaluation env with the training
    /// one). Errors when their dimension is not the environment's.
    pub fn set_state(&mut self, state: VecNormalizeState) -> Result<()> {
        state
            .validate()
            .map_err(|p| EnvError::Usage(format!("VecNormalize: {p}")))?;
        check_dim(&state, &self.venv).map_err(EnvError::Usage)?;
        self.state = state;
        Ok(())
    }

    /// Running statistics of the observations.
    pub fn obs_rms(&self) -> &RunningMeanStd {
        &self.state.obs_rms
    }

    /// Running statistics of the discounted return.
    pub fn ret_rms(&self) -> &RunningMeanStd {
        &self.state.ret_rms
    }

    /// Whether `reset` and `step` update the statistics.
    pub fn training(&self) -> bool {
        self.training
    }

    /// `false` freezes the statistics (evaluation).
    pub fn set_training(&mut self, training: bool) {
        self.training = training;
    }

    /// Normalises one observation (or several, row-major) with the current statistics.
    pub fn normalize_obs(&self, obs: &[f32]) -> Result<Vec<f32>> {
        self.state.normalize_obs(obs)
    }

    /// Normalises one reward with the current statistics.
    pub fn normalize_reward(&self, reward: f32) -> f32 {
        self.state.normalize_reward(reward)
    }

    /// The last observations before normalisation (SB3's `get_original_obs`).
    pub fn original_observations(&self) -> &[f32] {
        &self.raw_obs
    }

    /// The last rewards before normalisation (SB3's `get_original_reward`).
    pub fn original_rewards(&self) -> &[f32] {
        &self.raw_rewards
    }

    /// The terminal observation of the episode environment `i` finished at the last step,
    /// before normalisation.
    pub fn original_terminal_observation(&self, i: usize) -> Option<&[f32]> {
        self.raw_terminal.get(i)?.as_deref()
    }

    /// The wrapped vector environment.
    pub fn venv(&self) -> &V {
        &self.venv
    }

    /// The wrapped environment, mutably. Stepping or resetting it directly bypasses the
    /// normalisation and its buffers.
    pub fn venv_mut(&mut self) -> &mut V {
        &mut self.venv
    }

    /// The wrapped vector environment, dropping the statistics.
    pub fn into_inner(self) -> V {
        self.venv
    }
}

fn check_dim<V: VectorEnv>(state: &VecNormalizeState, venv: &V) -> std::result::Result<(), String> {
    if state.obs_dim() == venv.obs_dim() {
        Ok(())
    } else {
        Err(format!(
            "the statistics are for observations of {} values, the environment's have {}",
            state.obs_dim(),
            venv.obs_dim()
        ))
    }
}

impl<V: VectorEnv> VectorEnv for VecNormalize<V> {
    fn num_envs(&self) -> usize {
        self.venv.num_envs()
    }

    fn observation_space(&self) -> &BoxSpace {
        self.venv.observation_space()
    }

    fn action_space(&self) -> &BoxSpace {
        self.venv.action_space()
    }

    /// Resets the environments and the running returns; in training mode the first
    /// observations update the statistics.
    fn reset(&mut self, seed: Option<u64>) -> Result<&[f32]> {
        let raw = self.venv.reset(seed)?;
        self.raw_obs.copy_from_slice(raw);
        self.returns.fill(0.0);
        self.episode_ends.fill(None);
        self.raw_terminal.fill(None);
        if self.training && self.state.config.norm_obs {
            self.state.obs_rms.update(&self.raw_obs);
        }
        self.state.normalize_obs_into(&self.raw_obs, &mut self.obs);
        Ok(&self.obs)
    }

    fn reset_env(&mut self, index: usize, seed: Option<u64>) -> Result<&[f32]> {
        let raw = self.venv.reset_env(index, seed)?;
        let dim = raw.len();
        let range = index * dim..(index + 1) * dim;
        self.raw_obs[range.clone()].copy_from_slice(raw);
        self.returns[index] = 0.0;
        self.episode_ends[index] = None;
        self.raw_terminal[index] = None;
        if self.training && self.state.config.norm_obs {
            self.state.obs_rms.update(&self.raw_obs[range.clone()]);
        }
        self.state
            .normalize_obs_into(&self.raw_obs[range.clone()], &mut self.obs[range.clone()]);
        Ok(&self.obs[range])
    }

    fn privileged_dim(&self) -> usize {
        self.venv.privileged_dim()
    }

    /// Images pass through unnormalised (they stay bytes; the network scales them).
    fn image_space(&self) -> Option<&ImageSpace> {
        self.venv.image_space()
    }

    fn images(&self) -> &[u8] {
        self.venv.images()
    }

    fn reset_infos(&self) -> &[Info] {
        self.venv.reset_infos()
    }

    fn observations(&self) -> &[f32] {
        &self.obs
    }

    /// Steps the environments, then (SB3's `step_wait`): in training mode updates the
    /// observation statistics with the returned observations and the return statistics with
    /// the running returns; normalises observations, rewards and terminal observations; zeroes
    /// the running return of finished episodes.
    fn step(&mut self, actions: &[f32]) -> Result<VecStep<'_>> {
        let step = self.venv.step(actions)?;
        let state = &mut self.state;
        self.raw_obs.copy_from_slice(step.observations);
        self.raw_rewards.copy_from_slice(step.rewards);
        if self.training && state.config.norm_obs {
            state.obs_rms.update(&self.raw_obs);
        }
        state.normalize_obs_into(&self.raw_obs, &mut self.obs);
        if self.training {
            let gamma = state.config.gamma;
            for (ret, &r) in self.returns.iter_mut().zip(&self.raw_rewards) {
                *ret = *ret * gamma + r as f64;
            }
            state.ret_rms.update(&self.returns);
        }
        for (out, &r) in self.rewards.iter_mut().zip(&self.raw_rewards) {
            *out = state.normalize_reward(r);
        }
        for i in 0..step.num_envs() {
            match &step.episode_ends[i] {
                Some(end) => {
                    let mut normalised = end.clone();
                    state.normalize_obs_into(
                        &end.terminal_observation,
                        &mut normalised.terminal_observation,
                    );
                    self.raw_terminal[i] = Some(end.terminal_observation.clone());
                    self.episode_ends[i] = Some(normalised);
                }
                None => {
                    self.raw_terminal[i] = None;
                    self.episode_ends[i] = None;
                }
            }
            if step.done(i) {
                self.returns[i] = 0.0;
            }
        }
        Ok(VecStep {
            observations: &self.obs,
            rewards: &self.rewards,
            terminated: step.terminated,
            truncated: step.truncated,
            infos: step.infos,
            episode_ends: &self.episode_ends,
            obs_dim: step.obs_dim,
            images: step.images,
            image_len: step.image_len,
        })
    }

    fn close(&mut self) {
        self.venv.close()
    }
}
