//! Proximal Policy Optimization (Schulman et al. 2017), clipped objective, read top to bottom
//! like CleanRL's `ppo_continuous_action.py`.
//!
//! Per iteration: collect `n_steps` steps from every environment; compute GAE(λ) advantages;
//! for `n_epochs`, shuffle and split into minibatches of `batch_size`; minimise
//! `−min(r·A, clip(r, 1±ε)·A) + c_v·(V − R)² − c_e·H` with the global gradient norm clipped;
//! stop the epochs early when the approximate KL exceeds `target_kl`.
//!
//! With `privileged_critic` the value network also reads the environment's privileged state
//! (asymmetric actor-critic, Pinto et al. 2018), normalised by running statistics as
//! `VecNormalize` normalises observations; the policy reads the observation alone.

pub mod fused_loss;
pub mod pixel;

use crate::algorithm::{
    Algorithm, TensorMap, load_varmap, rng_from_state, rng_state, varmap_tensors,
};
use crate::buffers::RolloutBuffer;
use crate::error::{ConfigSection, Result, RlError};
use crate::nn::{Activation, Adam};
use crate::policies::actor_critic::ActorCritic;
use crate::policies::features::FeaturesConfig;
use crate::policies::net_config::NetConfig;
use candle_core::{DType, Device, Tensor};
use fairgrasp_env::{Info, RunningMeanStd, VecStep, VectorEnv};
use fused_loss::{FusedPpoLoss, LossCoefficients, Minibatch, MinibatchStats};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::nn::LrSchedule;

/// PPO hyperparameters. The defaults are the design's settings (SB3's PPO with the values of the
/// design document), kept as the `seed` preset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PpoConfig {
    /// Adam's step size (SB3's `learning_rate`; the start value under [`LrSchedule::Linear`]);
    /// positive.
    pub learning_rate: f64,
    /// How `learning_rate` changes over training.
    pub lr_schedule: LrSchedule,
    /// Steps per environment per rollout.
    pub n_steps: usize,
    /// Minibatch size.
    pub batch_size: usize,
    /// Passes over the rollout per update (SB3's `n_epochs`); at least 1.
    pub n_epochs: usize,
    /// Discount factor, in [0, 1].
    pub gamma: f32,
    /// GAE's λ (SB3's `gae_lambda`), trading the advantages' bias for variance; in [0, 1].
    pub gae_lambda: f32,
    /// ε of the clipped objective (SB3's `clip_range`): the probability ratio is clipped to
    /// 1 ± ε; in (0, 1).
    pub clip_range: f32,
    /// Clip the value update around the old values (None: no clipping, SB3's default).
    pub clip_range_vf: Option<f32>,
    /// Normalise each minibatch's advantages to zero mean and unit standard deviation.
    pub normalize_advantage: bool,
    /// Weight `c_e` of the entropy bonus (SB3's `ent_coef`); non-negative.
    pub ent_coef: f32,
    /// Weight `c_v` of the value loss (SB3's `vf_coef`); non-negative.
    pub vf_coef: f32,
    /// Bound on the global gradient norm of each step (SB3's `max_grad_norm`); ≤ 0: no clipping.
    pub max_grad_norm: f64,
    /// Stop an update's epochs early when a minibatch's approximate KL divergence, before its
    /// step, exceeds 1.5 × this (SB3's `target_kl` rule).
    pub target_kl: Option<f32>,
    /// Hidden layers of the policy and of the value network.
    pub net_arch: Vec<usize>,
    /// The activation after each hidden layer.
    pub activation: Activation,
    /// Initial log standard deviation of the Gaussian policy.
    pub log_std_init: f32,
    /// What the policy and value heads read (`kind = "flatten"`: the observation itself).
    pub features: FeaturesConfig,
    /// The value network also reads the environment's privileged state (`info.privileged`:
    /// for the arm tasks, `[readings] privileged = true`), which the policy never sees.
    /// Written only when on, so that other models' files read as before.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub privileged_critic: bool,
}

impl Default for PpoConfig {
    fn default() -> Self {
        Self {
            learning_rate: 3e-4,
            lr_schedule: LrSchedule::Constant,
            n_steps: 2048,
            batch_size: 256,
            n_epochs: 10,
            gamma: 0.99,
            gae_lambda: 0.95,
            clip_range: 0.2,
            clip_range_vf: None,
            normalize_advantage: true,
            ent_coef: 0.01,
            vf_coef: 0.5,
            max_grad_norm: 0.5,
            target_kl: None,
            net_arch: vec![64, 64],
            activation: Activation::Tanh,
            log_std_init: 0.0,
            features: FeaturesConfig::Flatten {},
            privileged_critic: false,
        }
    }
}

impl PpoConfig {
    /// The shape of the networks (the policy's part of these settings).
    pub fn net(&self) -> NetConfig {
        NetConfig {
            net_arch: self.net_arch.clone(),
            activation: self.activation,
            features: self.features.clone(),
        }
    }
}

/// The rollout buffer as tensors, for the loss through candle's autograd.
struct RolloutTensors {
    obs: Tensor,
    /// The observations followed by the privileged values, with a privileged critic.
    critic_obs: Option<Tensor>,
    actions: Tensor,
    log_probs: Tensor,
    advantages: Tensor,
    returns: Tensor,
    values: Tensor,
}

impl RolloutTensors {
    fn new(b: &RolloutBuffer) -> Result<Self> {
        let total = b.len();
        let dev = Device::Cpu;
        let obs = Tensor::from_slice(
            &b.observations[..total * b.obs_dim],
            (total, b.obs_dim),
            &dev,
        )?;
        let critic_obs = match b.privileged_dim {
            0 => None,
            pd => {
                let p = Tensor::from_slice(&b.privileged[..total * pd], (total, pd), &dev)?;
                Some(Tensor::cat(&[&obs, &p], 1)?)
            }
        };
        let column = |v: &[f32]| Tensor::from_slice(&v[..total], total, &dev);
        Ok(Self {
            actions: Tensor::from_slice(&b.actions[..total * b.act_dim], (total, b.act_dim), &dev)?,
            log_probs: column(&b.log_probs)?,
            advantages: column(&b.advantages)?,
            returns: column(&b.returns)?,
            values: column(&b.values)?,
            obs,
            critic_obs,
        })
    }
}

/// PPO's loss on the minibatch `batch` of `rollout` through candle's autograd, with its
/// statistics: the general path, for the settings the written-out loss does not compute.
fn tensor_loss(
    policy: &ActorCritic,
    c: &PpoConfig,
    rollout: &RolloutTensors,
    batch: &[u32],
) -> Result<(MinibatchStats, Tensor)> {
    let idx = Tensor::from_slice(batch, batch.len(), &Device::Cpu)?;
    let obs = rollout.obs.index_select(&idx, 0)?;
    let actions = rollout.actions.index_select(&idx, 0)?;
    let old_logp = rollout.log_probs.index_select(&idx, 0)?;
    let mut adv = rollout.advantages.index_select(&idx, 0)?;
    if c.normalize_advantage && batch.len() > 1 {
        let mean = adv.mean_all()?;
        let std = adv.broadcast_sub(&mean)?.sqr()?.mean_all()?.sqrt()?;
        adv = adv.broadcast_sub(&mean)?.broadcast_div(&(std + 1e-8)?)?;
    }
    let returns = rollout.returns.index_select(&idx, 0)?;

    // log π(a|s) and V(s) of the current policy.
    let critic_obs = match &rollout.critic_obs {
        Some(all) => Some(all.index_select(&idx, 0)?),
        None => None,
    };
    let (dist, values) = policy.forward(&obs, critic_obs.as_ref())?;
    let logp = dist.log_prob(&actions)?;
    let log_ratio = (&logp - &old_logp)?;
    let ratio = log_ratio.exp()?;

    // Clipped surrogate objective.
    let surrogate1 = (&ratio * &adv)?;
    let surrogate2 = (ratio.clamp(1.0 - c.clip_range, 1.0 + c.clip_range)? * &adv)?;
    let policy_loss = surrogate1.minimum(&surrogate2)?.mean_all()?.neg()?;

    // Value loss, optionally clipped around the old values.
    let value_loss = match c.clip_range_vf {
        None => (&values - &returns)?.sqr()?.mean_all()?,
        Some(eps) => {
            let old = rollout.values.index_select(&idx, 0)?;
            let clipped = (&old + (&values - &old)?.clamp(-eps, eps)?)?;
            let a = (&values - &returns)?.sqr()?;
            let b = (&clipped - &returns)?.sqr()?;
            a.maximum(&b)?.mean_all()?
        }
    };
    let entropy = dist.entropy()?.mean_all()?;
    let loss =
        ((&policy_loss + (&value_loss * c.vf_coef as f64)?)? - (&entropy * c.ent_coef as f64)?)?;

    // Diagnostics before the step (what SB3 logs).
    let approx_kl = ((&ratio - 1.0)? - &log_ratio)?
        .mean_all()?
        .to_scalar::<f32>()?;
    let clip_fraction = (&ratio - 1.0)?
        .abs()?
        .gt(c.clip_range as f64)?
        .to_dtype(DType::F32)?
        .mean_all()?
        .to_scalar::<f32>()?;
    let stats = MinibatchStats {
        policy_loss: policy_loss.to_scalar::<f32>()?,
        value_loss: value_loss.to_scalar::<f32>()?,
        entropy: entropy.to_scalar::<f32>()?,
        approx_kl,
        clip_fraction,
    };
    Ok((stats, loss))
}

/// The acting network of a saved model: the actor-critic (its value head included, so that
/// every tensor of `weights` is checked).
pub(crate) fn load_actor(
    weights: &TensorMap,
    obs_dim: usize,
    act_dim: usize,
    privileged_dim: usize,
    config: &PpoConfig,
) -> Result<ActorCritic> {
    let net = config.net();
    let policy = ActorCritic::zeroed(obs_dim, act_dim, privileged_dim, &net, config.log_std_init)?;
    load_varmap(&policy.varmap, weights)?;
    Ok(policy)
}

/// Statistics of one PPO update (SB3's `train/*` scalars).
/// The per-minibatch values are means over the minibatches stepped.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UpdateStats {
    /// Clipped surrogate loss (SB3's `train/policy_gradient_loss`).
    pub policy_loss: f32,
    /// Mean squared error of the values against the returns.
    pub value_loss: f32,
    /// The policy's entropy (nats); logged negated as `train/entropy_loss`.
    pub entropy: f32,
    /// Approximate KL divergence of the new policy from the old, `mean((r − 1) − log r)`.
    pub approx_kl: f32,
    /// Fraction of samples whose ratio `r` lies outside 1 ± `clip_range`.
    pub clip_fraction: f32,
    /// [`explained_variance`] of the rollout's values against its returns, before the update.
    pub explained_variance: f32,
    /// Global gradient norm before clipping.
    pub grad_norm: f32,
    /// The learning rate of this update (after the schedule).
    pub learning_rate: f64,
    /// Mean standard deviation of the Gaussian policy after the update (`exp(log_std)`).
    pub std: f32,
    /// Epochs completed; fewer than `n_epochs` when `target_kl` stopped the update.
    pub epochs_run: usize,
}

/// The PPO learner: policy, optimiser, rollout buffer and random stream.
pub struct Ppo {
    /// The hyperparameters.
    pub config: PpoConfig,
    /// The policy and value networks.
    pub policy: ActorCritic,
    /// Adam over all of the policy's variables.
    pub optimizer: Adam,
    /// The current iteration's rollout.
    pub buffer: RolloutBuffer,
    /// Random stream for action sampling and minibatch shuffling.
    pub rng: ChaCha8Rng,
    /// Environment steps taken so far (all environments together).
    pub num_timesteps: u64,
    /// Whether each environment's current observation starts an episode (SB3's
    /// `_last_episode_starts`).
    episode_starts: Vec<bool>,
    /// Whether updates run the loss written out ([`crate::ppo::fused_loss`]) where it supports the
    /// configuration; off, candle's autograd computes the same weights, slower.
    pub written_out_loss: bool,
    fused: FusedPpoLoss,
    minibatch: MinibatchData,
    /// With `privileged_critic`: each environment's privileged state and its statistics.
    privileged: Option<PrivilegedState>,
}

/// The privileged critic's extra inputs: each environment's privileged state for its current
/// observation, normalised by running statistics (clipped at ±10, VecNormalize's rule).
struct PrivilegedState {
    dim: usize,
    /// `n_envs × dim`, normalised.
    rows: Vec<f32>,
    stats: RunningMeanStd,
}

impl PrivilegedState {
    const CLIP: f64 = 10.0;
    const EPSILON: f64 = 1e-8;

    fn new(dim: usize) -> Self {
        Self {
            dim,
            rows: Vec::new(),
            stats: RunningMeanStd::new(dim),
        }
    }

    /// `info`'s privileged state, checked.
    fn of<'i>(&self, env: usize, info: &'i Info) -> Result<&'i [f32]> {
        if info.privileged.len() != self.dim || info.privileged.iter().any(|v| !v.is_finite()) {
            return Err(RlError::Other(format!(
                "env {env}: the privileged critic needs {} finite privileged values per step \
                 (info.privileged), got {:?}",
                self.dim, info.privileged
            )));
        }
        Ok(&info.privileged)
    }

    /// Appends `raw`, normalised with the current statistics, to `out`.
    fn normalize_into(&self, raw: &[f32], out: &mut Vec<f32>) {
        let start = out.len();
        out.resize(start + raw.len(), 0.0);
        (self.stats).normalize_into(raw, Self::EPSILON, Self::CLIP, &mut out[start..]);
    }

    /// Takes each environment's current privileged state (from `infos`), updating the
    /// statistics with them first.
    fn set_rows<'i>(&mut self, infos: impl Iterator<Item = &'i Info>) -> Result<()> {
        let mut raw = Vec::new();
        for (env, info) in infos.enumerate() {
            raw.extend_from_slice(self.of(env, info)?);
        }
        self.stats.update(&raw);
        let mut rows = Vec::with_capacity(raw.len());
        for row in raw.chunks_exact(self.dim) {
            self.normalize_into(row, &mut rows);
        }
        self.rows = rows;
        Ok(())
    }

    /// The rows after `step`: the step's own for running episodes, the reset's for those that
    /// ended.
    fn advance(&mut self, step: &VecStep<'_>) -> Result<()> {
        let current = step
            .infos
            .iter()
            .zip(step.episode_ends)
            .map(|(info, end)| end.as_ref().map_or(info, |end| &end.reset_info));
        self.set_rows(current)
    }

    /// The value network's input for the current observations `obs`: each row followed by its
    /// environment's privileged state, written into `out`.
    fn critic_input<'o>(&self, obs: &[f32], obs_dim: usize, out: &'o mut Vec<f32>) -> &'o [f32] {
        out.clear();
        for (o, p) in obs
            .chunks_exact(obs_dim)
            .zip(self.rows.chunks_exact(self.dim))
        {
            out.extend_from_slice(o);
            out.extend_from_slice(p);
        }
        out
    }

    /// The value network's input for environment `env`'s terminal observation, whose
    /// privileged state is in the final step's `info`.
    fn terminal_input<'o>(
        &self,
        env: usize,
        info: &Info,
        terminal_observation: &[f32],
        out: &'o mut Vec<f32>,
    ) -> Result<&'o [f32]> {
        out.clear();
        out.extend_from_slice(terminal_observation);
        self.normalize_into(self.of(env, info)?, out);
        Ok(out)
    }
}

/// One minibatch gathered from the rollout buffer, row-major.
#[derive(Default)]
struct MinibatchData {
    observations: Vec<f32>,
    /// Observations joined with their privileged states (privileged critic only).
    critic_inputs: Vec<f32>,
    actions: Vec<f32>,
    log_probs: Vec<f32>,
    advantages: Vec<f32>,
    returns: Vec<f32>,
}

impl MinibatchData {
    fn gather(&mut self, b: &RolloutBuffer, indices: &[u32]) {
        let (od, ad, pd) = (b.obs_dim, b.act_dim, b.privileged_dim);
        self.observations.clear();
        self.critic_inputs.clear();
        self.actions.clear();
        self.log_probs.clear();
        self.advantages.clear();
        self.returns.clear();
        for &i in indices {
            let i = i as usize;
            self.observations
                .extend_from_slice(&b.observations[i * od..(i + 1) * od]);
            if pd > 0 {
                self.critic_inputs
                    .extend_from_slice(&b.observations[i * od..(i + 1) * od]);
                self.critic_inputs
                    .extend_from_slice(&b.privileged[i * pd..(i + 1) * pd]);
            }
            self.actions
                .extend_from_slice(&b.actions[i * ad..(i + 1) * ad]);
            self.log_probs.push(b.log_probs[i]);
            self.advantages.push(b.advantages[i]);
            self.returns.push(b.returns[i]);
        }
    }

    fn as_minibatch(&self) -> Minibatch<'_> {
        let value_inputs = match self.critic_inputs.is_empty() {
            true => &self.observations,
            false => &self.critic_inputs,
        };
        Minibatch {
            observations: &self.observations,
            value_inputs,
            actions: &self.actions,
            old_log_probs: &self.log_probs,
            advantages: &self.advantages,
            returns: &self.returns,
        }
    }
}

impl Ppo {
    /// A learner for `n_envs` environments (`obs_dim` observation values, `act_dim` action
    /// values), its networks initialised from `seed`; fails on an invalid configuration.
    pub fn new(
        config: PpoConfig,
        obs_dim: usize,
        act_dim: usize,
        n_envs: usize,
        seed: u64,
    ) -> Result<Self> {
        Self::with_privileged(config, obs_dim, act_dim, 0, n_envs, seed)
    }

    /// [`Self::new`] for environments that report `privileged_dim` privileged values
    /// ([`VectorEnv::privileged_dim`]); the value network reads them when the configuration's
    /// `privileged_critic` is on.
    pub fn with_privileged(
        config: PpoConfig,
        obs_dim: usize,
        act_dim: usize,
        privileged_dim: usize,
        n_envs: usize,
        seed: u64,
    ) -> Result<Self> {
        validate(&config, n_envs)?;
        let privileged_dim = match (config.privileged_critic, privileged_dim) {
            (false, _) => 0,
            (true, 0) => {
                return Err(RlError::Config {
                    key: "ppo.privileged_critic".into(),
                    problem: "the environment reports no privileged state (for the arm tasks: \
                              set [env.readings] privileged = true)"
                        .into(),
                });
            }
            (true, dim) => dim,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let policy = ActorCritic::new(
            obs_dim,
            act_dim,
            privileged_dim,
            &config.net(),
            config.log_std_init,
            &mut rng,
        )?;
        let optimizer = Adam::new(&policy.varmap, config.learning_rate)?;
        let buffer = RolloutBuffer::new(config.n_steps, n_envs, obs_dim, act_dim)
            .with_privileged(privileged_dim);
        Ok(Self {
            buffer,
            rng,
            config,
            policy,
            optimizer,
            num_timesteps: 0,
            episode_starts: Vec::new(),
            written_out_loss: true,
            fused: FusedPpoLoss::default(),
            minibatch: MinibatchData::default(),
            privileged: (privileged_dim > 0).then(|| PrivilegedState::new(privileged_dim)),
        })
    }

    /// Threads for the update: with 2 or more, the value head's passes run beside the policy's
    /// (the same weights, bit for bit). `new` starts with one.
    pub fn set_update_threads(&mut self, threads: usize) -> Result<()> {
        self.fused.set_threads(threads)
    }

    /// Fills the rollout buffer from `venv`, starting from its current observations.
    /// `on_step` sees every vector step (for episode statistics).
    pub fn collect_rollout<V: VectorEnv>(
        &mut self,
        venv: &mut V,
        on_step: &mut dyn FnMut(&VecStep<'_>),
    ) -> Result<()> {
        let space = venv.action_space().clone();
        let (n, od) = (venv.num_envs(), venv.obs_dim());
        if self.episode_starts.len() != n {
            // A fresh learner (or one resumed onto freshly reset environments).
            self.episode_starts = vec![true; n];
            if let Some(p) = self.privileged.as_mut() {
                p.set_rows(venv.reset_infos().iter())?;
            }
        }
        let episode_starts = &mut self.episode_starts;
        self.buffer.clear();
        let mut obs = venv.observations().to_vec();
        let mut clipped = vec![0.0; n * space.dim()];
        let (mut critic_obs, mut terminal) = (Vec::new(), Vec::new());
        while !self.buffer.is_full() {
            let privileged = self.privileged.as_ref();
            let critic = privileged.map(|p| p.critic_input(&obs, od, &mut critic_obs));
            let out = (self.policy).act_with_critic(&obs, critic, false, &mut self.rng)?;
            clipped.copy_from_slice(&out.actions);
            for row in clipped.chunks_mut(space.dim()) {
                space.clip(row);
            }
            let step = venv.step(&clipped)?;
            on_step(&step);
            let mut rewards = step.rewards.to_vec();
            // Bootstrap truncated episodes from their real final observation.
            for (i, end) in step.episode_ends.iter().enumerate() {
                if let (Some(end), true) = (end, step.truncated[i]) {
                    let last = &end.terminal_observation;
                    let v = match &self.privileged {
                        Some(p) => {
                            let info = &step.infos[i];
                            self.policy
                                .values(p.terminal_input(i, info, last, &mut terminal)?)?
                        }
                        None => self.policy.values(last)?,
                    }[0];
                    rewards[i] += self.config.gamma * v;
                }
            }
            let privileged = self.privileged.as_ref().map_or(&[][..], |p| &p.rows);
            self.buffer.push(
                &obs,
                &out.actions,
                &rewards,
                episode_starts,
                &out.values,
                &out.log_probs,
                privileged,
            );
            if let Some(p) = self.privileged.as_mut() {
                p.advance(&step)?;
            }
            obs.copy_from_slice(step.observations);
            for (i, start) in episode_starts.iter_mut().enumerate() {
                *start = step.terminated[i] || step.truncated[i];
            }
            self.num_timesteps += n as u64;
        }
        let last_values = match &self.privileged {
            Some(p) => self
                .policy
                .values(p.critic_input(&obs, od, &mut critic_obs))?,
            None => self.policy.values(&obs)?,
        };
        self.buffer.compute_returns_and_advantages(
            &last_values,
            episode_starts,
            self.config.gamma,
            self.config.gae_lambda,
        );
        Ok(())
    }

    /// One PPO update on the collected rollout. `progress_remaining` goes from 1 to 0 over
    /// training (for the learning-rate schedule).
    pub fn update(&mut self, progress_remaining: f64) -> Result<UpdateStats> {
        let c = self.config.clone();
        let lr = c.lr_schedule.at(c.learning_rate, progress_remaining);
        self.optimizer.lr = lr;
        let b = &self.buffer;
        let total = b.len();
        let explained_variance = explained_variance(&b.values[..total], &b.returns[..total]);
        // The written-out loss computes the default actor-critic's (tanh heads on flat
        // observations, no value clipping); other settings run the tensor code.
        let written_out = self.written_out_loss
            && c.activation == Activation::Tanh
            && c.clip_range_vf.is_none()
            && c.features == FeaturesConfig::Flatten {};
        let rollout = match written_out {
            true => None,
            false => Some(RolloutTensors::new(&self.buffer)?),
        };
        let coefficients = LossCoefficients {
            clip_range: c.clip_range,
            ent_coef: c.ent_coef,
            vf_coef: c.vf_coef,
            normalize_advantage: c.normalize_advantage,
        };
        let names: Vec<String> = self.optimizer.vars().map(|(n, _)| n.to_string()).collect();
        let names: Vec<&str> = names.iter().map(String::as_str).collect();

        let mut indices: Vec<u32> = (0..total as u32).collect();
        let mut stats = UpdateStats {
            learning_rate: lr,
            explained_variance,
            ..UpdateStats::default()
        };
        let (mut sum, mut gn_sum, mut count) = (MinibatchStats::default(), 0.0, 0usize);
        'epochs: for epoch in 0..c.n_epochs {
            indices.shuffle(&mut self.rng);
            for batch in indices.chunks(c.batch_size) {
                let (s, loss) = match &rollout {
                    None => {
                        self.minibatch.gather(&self.buffer, batch);
                        let (pi, vf) = self.policy.heads();
                        let s = self.fused.compute(
                            (pi, vf, self.policy.log_std()),
                            &coefficients,
                            &self.minibatch.as_minibatch(),
                        )?;
                        (s, None)
                    }
                    Some(rollout) => {
                        let (s, loss) = tensor_loss(&self.policy, &c, rollout, batch)?;
                        (s, Some(loss))
                    }
                };
                // SB3's early stop, on the KL divergence before the step.
                if let Some(target) = c.target_kl
                    && s.approx_kl > 1.5 * target
                {
                    stats.epochs_run = epoch;
                    break 'epochs;
                }
                let grad_norm = match loss {
                    None => (self.optimizer)
                        .step_with(&self.fused.gradients(&names), c.max_grad_norm)?,
                    Some(loss) => self.optimizer.backward_step(&loss, c.max_grad_norm)?,
                };
                sum.policy_loss += s.policy_loss;
                sum.value_loss += s.value_loss;
                sum.entropy += s.entropy;
                sum.approx_kl += s.approx_kl;
                sum.clip_fraction += s.clip_fraction;
                gn_sum += grad_norm as f32;
                count += 1;
            }
            stats.epochs_run = epoch + 1;
        }
        let n = count.max(1) as f32;
        stats.policy_loss = sum.policy_loss / n;
        stats.value_loss = sum.value_loss / n;
        stats.entropy = sum.entropy / n;
        stats.approx_kl = sum.approx_kl / n;
        stats.clip_fraction = sum.clip_fraction / n;
        stats.grad_norm = gn_sum / n;
        stats.std = self
            .policy
            .log_std()
            .exp()?
            .mean_all()?
            .to_scalar::<f32>()?;
        Ok(stats)
    }
}

impl Algorithm for Ppo {
    fn name(&self) -> &'static str {
        "ppo"
    }

    fn num_timesteps(&self) -> u64 {
        self.num_timesteps
    }

    fn set_num_timesteps(&mut self, steps: u64) {
        self.num_timesteps = steps;
    }

    fn learn_iteration<V: VectorEnv>(
        &mut self,
        venv: &mut V,
        progress_remaining: f64,
        on_step: &mut dyn FnMut(&VecStep<'_>),
    ) -> Result<Vec<(&'static str, f32)>> {
        self.collect_rollout(venv, on_step)?;
        let s = self.update(progress_remaining)?;
        Ok(vec![
            ("train/policy_gradient_loss", s.policy_loss),
            ("train/value_loss", s.value_loss),
            ("train/entropy_loss", -s.entropy),
            ("train/approx_kl", s.approx_kl),
            ("train/clip_fraction", s.clip_fraction),
            ("train/explained_variance", s.explained_variance),
            ("train/learning_rate", s.learning_rate as f32),
            ("train/std", s.std),
            ("train/grad_norm", s.grad_norm),
        ])
    }

    fn predict(&mut self, obs: &[f32], deterministic: bool) -> Result<Vec<f32>> {
        self.policy.predict(obs, deterministic, &mut self.rng)
    }

    fn weights(&self) -> Result<TensorMap> {
        Ok(varmap_tensors(&self.policy.varmap, ""))
    }

    fn load_weights(&mut self, weights: &TensorMap) -> Result<()> {
        load_varmap(&self.policy.varmap, weights)
    }

    fn training_state(&self) -> Result<TensorMap> {
        let mut state = self.optimizer.state()?;
        state.extend(rng_state(&self.rng, "ppo.")?);
        if let Some(p) = &self.privileged {
            let dev = Device::Cpu;
            let stats = &p.stats;
            state.insert(PRIVILEGED_MEAN.into(), Tensor::new(stats.mean(), &dev)?);
            state.insert(PRIVILEGED_VAR.into(), Tensor::new(stats.var(), &dev)?);
            state.insert(
                PRIVILEGED_COUNT.into(),
                Tensor::new(&[stats.count()], &dev)?,
            );
        }
        Ok(state)
    }

    fn load_training_state(&mut self, state: &TensorMap) -> Result<()> {
        self.optimizer.load_state(state).map_err(RlError::Model)?;
        self.rng = rng_from_state(state, "ppo.")?;
        if let Some(p) = self.privileged.as_mut() {
            let get = |key: &str| -> Result<Vec<f64>> {
                let t = state
                    .get(key)
                    .ok_or_else(|| RlError::Model(format!("the training state lacks `{key}`")))?;
                t.to_vec1::<f64>()
                    .map_err(|e| RlError::Model(format!("`{key}`: {e}")))
            };
            let count = get(PRIVILEGED_COUNT)?.first().copied().unwrap_or(f64::NAN);
            p.stats =
                RunningMeanStd::from_parts(get(PRIVILEGED_MEAN)?, get(PRIVILEGED_VAR)?, count)
                    .and_then(|s| match s.dim() == p.dim {
                        true => Ok(s),
                        false => Err(format!("{} values, the critic reads {}", s.dim(), p.dim)),
                    })
                    .map_err(|e| RlError::Model(format!("privileged-state statistics: {e}")))?;
        }
        Ok(())
    }

    fn rng_mut(&mut self) -> &mut ChaCha8Rng {
        &mut self.rng
    }
}

/// Training-state names of the privileged critic's running statistics.
const PRIVILEGED_MEAN: &str = "ppo.privileged.mean";
const PRIVILEGED_VAR: &str = "ppo.privileged.var";
const PRIVILEGED_COUNT: &str = "ppo.privileged.count";

/// `1 − Var(returns − values) / Var(returns)`: how much of the return the value function explains.
pub fn explained_variance(values: &[f32], returns: &[f32]) -> f32 {
    let n = returns.len().max(1) as f32;
    let mean_r = returns.iter().sum::<f32>() / n;
    let var_r = returns.iter().map(|r| (r - mean_r).powi(2)).sum::<f32>() / n;
    if var_r == 0.0 {
        return f32::NAN;
    }
    let diff: Vec<f32> = returns.iter().zip(values).map(|(r, v)| r - v).collect();
    let mean_d = diff.iter().sum::<f32>() / n;
    let var_d = diff.iter().map(|d| (d - mean_d).powi(2)).sum::<f32>() / n;
    1.0 - var_d / var_r
}

pub(crate) fn validate(c: &PpoConfig, n_envs: usize) -> Result<()> {
    let section = ConfigSection("ppo");
    section.positive("learning_rate", c.learning_rate)?;
    section.at_least_one("n_steps", c.n_steps)?;
    if c.batch_size == 0 || c.batch_size > c.n_steps * n_envs {
        return section.bad(
            "batch_size",
            format!(
                "must be in 1..={} (n_steps × n_envs), got {}",
                c.n_steps * n_envs,
                c.batch_size
            ),
        );
    }
    section.at_least_one("n_epochs", c.n_epochs)?;
    section.in_unit_interval("gamma", c.gamma)?;
    section.in_unit_interval("gae_lambda", c.gae_lambda)?;
    if !(c.clip_range > 0.0 && c.clip_range < 1.0) {
        return section.bad(
            "clip_range",
            format!("must be in (0, 1), got {}", c.clip_range),
        );
    }
    section.net_arch(&c.net_arch)?;
    section.non_negative("ent_coef", c.ent_coef)?;
    section.non_negative("vf_coef", c.vf_coef)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::assert_close;
    use fairgrasp_env::random::standard_normal;
    use rand::Rng;

    /// A learner with a synthetic rollout (the same for the same seeds); with a privileged
    /// critic, 4 privileged values per observation.
    fn learner(config: &PpoConfig, written_out: bool) -> Ppo {
        let (obs_dim, act_dim, n_envs) = (5, 3, 2);
        let pd = if config.privileged_critic { 4 } else { 0 };
        let mut ppo =
            Ppo::with_privileged(config.clone(), obs_dim, act_dim, pd, n_envs, 4).unwrap();
        ppo.written_out_loss = written_out;
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut obs = vec![0.0f32; n_envs * obs_dim];
        let mut privileged = vec![0.0f32; n_envs * pd];
        while !ppo.buffer.is_full() {
            obs.iter_mut().for_each(|v| *v = standard_normal(&mut rng));
            privileged
                .iter_mut()
                .for_each(|v| *v = standard_normal(&mut rng));
            let critic_obs: Vec<f32> = (obs.chunks(obs_dim).zip(privileged.chunks(pd.max(1))))
                .flat_map(|(o, p)| o.iter().chain(&p[..pd]).copied())
                .collect();
            let critic = (pd > 0).then_some(critic_obs.as_slice());
            let out = (ppo.policy)
                .act_with_critic(&obs, critic, false, &mut ppo.rng)
                .unwrap();
            let rewards: Vec<f32> = (0..n_envs).map(|_| rng.random::<f32>()).collect();
            let starts: Vec<bool> = (0..n_envs).map(|_| rng.random::<f32>() < 0.1).collect();
            ppo.buffer.push(
                &obs,
                &out.actions,
                &rewards,
                &starts,
                &out.values,
                &out.log_probs,
                &privileged,
            );
        }
        ppo.buffer
            .compute_returns_and_advantages(&[0.5, -0.5], &[false, true], 0.9, 0.95);
        ppo
    }

    /// The written-out update against the tensor code's: the same arithmetic, its matrix
    /// products summed in another order (the same on every host), so the same weights to
    /// rounding after each update.
    #[test]
    fn trains_the_weights_of_candles_autograd() {
        let base = PpoConfig {
            n_steps: 40,
            batch_size: 16,
            n_epochs: 3,
            net_arch: vec![8, 6],
            ..PpoConfig::default()
        };
        let variants = [
            base.clone(),
            PpoConfig {
                ent_coef: 0.0,
                log_std_init: -0.5,
                ..base.clone()
            },
            PpoConfig {
                normalize_advantage: false,
                max_grad_norm: 100.0,
                clip_range: 0.05,
                ..base.clone()
            },
            PpoConfig {
                privileged_critic: true,
                ..base.clone()
            },
        ];
        // One thread, and the value head on a second thread beside the policy's.
        for (config, threads) in variants.into_iter().flat_map(|c| [(c.clone(), 1), (c, 2)]) {
            let (mut ours, mut reference) = (learner(&config, true), learner(&config, false));
            ours.set_update_threads(threads).unwrap();
            for round in 0..3 {
                let (a, b) = (ours.update(1.0).unwrap(), reference.update(1.0).unwrap());
                let scalars = |s: &UpdateStats| {
                    [
                        s.policy_loss,
                        s.value_loss,
                        s.entropy,
                        s.approx_kl,
                        s.clip_fraction,
                        s.explained_variance,
                        s.grad_norm,
                        s.std,
                    ]
                };
                let what = format!("update {round} statistics, {threads} threads, {config:?}");
                assert_close(&scalars(&a), &scalars(&b), &what);
                assert_eq!(
                    (a.learning_rate, a.epochs_run),
                    (b.learning_rate, b.epochs_run),
                    "{what}"
                );
                let (wa, wb) = (ours.weights().unwrap(), reference.weights().unwrap());
                for (name, t) in &wa {
                    let x: Vec<f32> = t.flatten_all().unwrap().to_vec1().unwrap();
                    let y: Vec<f32> = wb[name].flatten_all().unwrap().to_vec1().unwrap();
                    let what = format!("`{name}` after update {round}, {threads} threads");
                    assert_close(&x, &y, &what);
                }
            }
        }
    }
}
