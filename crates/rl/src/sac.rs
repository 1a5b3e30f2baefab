//! Soft Actor-Critic (Haarnoja et al. 2018) with twin critics and a learnt entropy coefficient,
//! read top to bottom like CleanRL's `sac_continuous_action.py`, with SB3's SAC semantics.
//!
//! Per iteration: one step of every environment (uniformly random actions for the first
//! `learning_starts` steps), its transitions into the replay buffer, then on average `utd_ratio`
//! gradient steps per transition. A gradient step, on a minibatch `(s, a, r, s', d)`:
//! - critics: `y = r + γ (1 − d) (min Q'(s', a') − α log π(a'|s'))`, `a' ~ π(·|s')`, minimise
//!   `½ Σᵢ (Qᵢ(s, a) − y)²`;
//! - actor: minimise `α log π(ã|s) − min Q(s, ã)`, `ã ~ π(·|s)` reparameterised;
//! - entropy coefficient (when learnt): minimise `−log α · (log π(ã|s) + H̄)`;
//! - target critics: `Q' ← (1 − τ) Q' + τ Q`.
//!
//! `d` is termination only: a truncated episode is bootstrapped from its real last observation.
//! The policy is a tanh-squashed Gaussian, so actions lie in `[-1, 1]`: the environments must
//! act in that box (the driver wraps them in `RescaleAction`).

use crate::algorithm::{
    Algorithm, TensorMap, load_varmap, rng_from_state, rng_state, varmap_tensors,
};
use crate::buffers::{ReplayBuffer, ReplaySample};
use crate::distributions::standard_normal_tensor;
use crate::error::{Result, RlError};
use crate::nn::{Activation, Adam};
use crate::policies::features::FeaturesConfig;
use crate::policies::sac_policy::{SacActor, SacPolicy};
use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use fairgrasp_env::{VecStep, VectorEnv};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// SAC hyperparameters (SB3's names and defaults where they exist).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SacConfig {
    pub learning_rate: f64,
    /// Replay buffer capacity (transitions).
    pub buffer_size: usize,
    /// Environment steps (all envs together) of uniformly random actions before learning.
    pub learning_starts: u64,
    pub batch_size: usize,
    /// Polyak coefficient of the target critics.
    pub tau: f32,
    pub gamma: f32,
    /// Gradient steps per environment transition (update-to-data ratio).
    pub utd_ratio: f32,
    /// Fixed entropy coefficient; `None` tunes it automatically (SB3's `"auto"`).
    pub ent_coef: Option<f32>,
    /// Initial entropy coefficient when tuned automatically.
    pub ent_coef_init: f32,
    /// Target entropy; `None` means −(action dimensions).
    pub target_entropy: Option<f32>,
    /// Hidden layers of the actor and of each critic.
    pub net_arch: Vec<usize>,
    pub activation: Activation,
    /// Save the replay buffer in checkpoints, so a resumed run keeps its experience.
    pub save_replay_buffer: bool,
    /// What the actor and the critics read (`kind = "flatten"`: the observation itself).
    pub features: FeaturesConfig,
}

impl Default for SacConfig {
    fn default() -> Self {
        Self {
            learning_rate: 3e-4,
            buffer_size: 1_000_000,
            learning_starts: 10_000,
            batch_size: 256,
            tau: 0.005,
            gamma: 0.99,
            utd_ratio: 1.0,
            ent_coef: None,
            ent_coef_init: 1.0,
            target_entropy: None,
            net_arch: vec![256, 256],
            activation: Activation::Relu,
            save_replay_buffer: true,
            features: FeaturesConfig::Flatten {},
        }
    }
}

pub(crate) fn validate(c: &SacConfig, _n_envs: usize) -> Result<()> {
    let bad = |key: &str, problem: String| {
        Err(RlError::Config {
            key: format!("sac.{key}"),
            problem,
        })
    };
    if !(c.learning_rate.is_finite() && c.learning_rate > 0.0) {
        return bad(
            "learning_rate",
            format!("must be positive, got {}", c.learning_rate),
        );
    }
    if c.buffer_size == 0 {
        return bad("buffer_size", "must be at least 1".into());
    }
    if c.batch_size == 0 {
        return bad("batch_size", "must be at least 1".into());
    }
    if !(c.tau > 0.0 && c.tau <= 1.0) {
        return bad("tau", format!("must be in (0, 1], got {}", c.tau));
    }
    if !(0.0..=1.0).contains(&c.gamma) {
        return bad("gamma", format!("must be in [0, 1], got {}", c.gamma));
    }
    if !(c.utd_ratio.is_finite() && c.utd_ratio > 0.0) {
        return bad(
            "utd_ratio",
            format!("must be positive, got {}", c.utd_ratio),
        );
    }
    if let Some(v) = c.ent_coef
        && !(v.is_finite() && v >= 0.0)
    {
        return bad("ent_coef", format!("must be non-negative, got {v}"));
    }
    // Taken as a logarithm, so it must be positive even where a fixed `ent_coef` overrides it.
    if !(c.ent_coef_init.is_finite() && c.ent_coef_init > 0.0) {
        return bad(
            "ent_coef_init",
            format!("must be positive, got {}", c.ent_coef_init),
        );
    }
    if let Some(v) = c.target_entropy
        && !v.is_finite()
    {
        return bad("target_entropy", format!("must be finite, got {v}"));
    }
    if c.net_arch.is_empty() || c.net_arch.contains(&0) {
        return bad(
            "net_arch",
            "needs at least one hidden layer, all of positive width".into(),
        );
    }
    Ok(())
}

/// Every network of the learner: the policy's and log α. Variable names carry their group's
/// prefix (`actor.`, `critic.`, `critic_target.`, `log_alpha`), so saved weights and errors
/// name tensors unambiguously.
pub(crate) struct Networks {
    pub(crate) policy: SacPolicy,
    /// log α, when it is learnt (`ent_coef = None`).
    log_alpha: Option<(VarMap, Var)>,
}

impl Networks {
    /// The networks with zero weights (log α at its initial value).
    pub(crate) fn zeroed(obs_dim: usize, act_dim: usize, config: &SacConfig) -> Result<Self> {
        let log_alpha = match config.ent_coef {
            Some(_) => None,
            None => {
                let varmap = VarMap::new();
                let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
                let init = candle_nn::Init::Const((config.ent_coef_init as f64).ln());
                vb.get_with_hints(1, "log_alpha", init)?;
                let var = var(&varmap, "log_alpha")?;
                Some((varmap, var))
            }
        };
        Ok(Self {
            policy: SacPolicy::zeroed(obs_dim, act_dim, config)?,
            log_alpha,
        })
    }

    /// The groups of variables with their name prefixes, in a fixed order.
    fn groups(&self) -> Vec<(&'static str, &VarMap)> {
        let mut groups = self.policy.groups().to_vec();
        if let Some((varmap, _)) = &self.log_alpha {
            groups.push(("log_alpha", varmap));
        }
        groups
    }

    fn weights(&self) -> TensorMap {
        let mut out = TensorMap::new();
        for (_, varmap) in self.groups() {
            out.extend(varmap_tensors(varmap, ""));
        }
        out
    }

    /// Loads weights saved by [`Self::weights`]; `obs_dim`, `act_dim` and `config` must be
    /// those the networks were built with. A missing, extra or mis-shaped tensor is an error
    /// that names it, and changes nothing.
    pub(crate) fn load_weights(
        &self,
        weights: &TensorMap,
        obs_dim: usize,
        act_dim: usize,
        config: &SacConfig,
    ) -> Result<()> {
        let groups = self.groups();
        let mut parts = vec![TensorMap::new(); groups.len()];
        for (name, t) in weights {
            let Some(g) = groups.iter().position(|(p, _)| name.starts_with(p)) else {
                return Err(RlError::Model(format!(
                    "the weights hold tensor `{name}`, which this network does not have"
                )));
            };
            parts[g].insert(name.clone(), t.clone());
        }
        // `load_varmap` checks one group before changing it; trying every group on scratch
        // networks first means a mismatch in a later group leaves the earlier ones untouched.
        let scratch = Networks::zeroed(obs_dim, act_dim, config)?;
        for ((_, varmap), part) in scratch.groups().into_iter().zip(&parts) {
            load_varmap(varmap, part)?;
        }
        for ((_, varmap), part) in groups.into_iter().zip(&parts) {
            load_varmap(varmap, part)?;
        }
        Ok(())
    }

    /// The actor alone (for acting).
    pub(crate) fn into_actor(self) -> SacActor {
        self.policy.actor
    }
}

/// The variable `name` of `varmap`.
fn var(varmap: &VarMap, name: &str) -> Result<Var> {
    varmap
        .data()
        .lock()
        .expect("varmap lock")
        .get(name)
        .cloned()
        .ok_or_else(|| RlError::Other(format!("parameter `{name}` missing")))
}

/// Means of the losses of the gradient steps of one iteration.
#[derive(Default)]
struct StepStats {
    actor_loss: f32,
    critic_loss: f32,
    ent_coef: f32,
    ent_coef_loss: f32,
}

/// The SAC learner: networks, optimisers, replay buffer and random stream.
pub struct Sac {
    pub config: SacConfig,
    nets: Networks,
    actor_opt: Adam,
    critic_opt: Adam,
    /// The optimiser of log α, when it is learnt.
    alpha_opt: Option<Adam>,
    target_entropy: f32,
    buffer: ReplayBuffer,
    /// Reused minibatch storage.
    sample: ReplaySample,
    rng: ChaCha8Rng,
    num_timesteps: u64,
    /// Gradient steps owed but not yet taken (fractional when `utd_ratio × n_envs` is not an
    /// integer).
    grad_accumulator: f64,
    /// Gradient steps taken so far.
    n_updates: u64,
    obs_dim: usize,
    act_dim: usize,
}

impl Sac {
    pub fn new(
        config: SacConfig,
        obs_dim: usize,
        act_dim: usize,
        n_envs: usize,
        seed: u64,
    ) -> Result<Self> {
        validate(&config, n_envs)?;
        if obs_dim == 0 || act_dim == 0 {
            return Err(RlError::Other(format!(
                "SAC needs observations and actions, got {obs_dim} and {act_dim} values"
            )));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let nets = Networks::zeroed(obs_dim, act_dim, &config)?;
        nets.policy.init_weights(&mut rng)?;
        let lr = config.learning_rate;
        Ok(Self {
            actor_opt: Adam::new(&nets.policy.actor.varmap, lr)?,
            critic_opt: Adam::new(&nets.policy.critic.varmap, lr)?,
            alpha_opt: match &nets.log_alpha {
                Some((varmap, _)) => Some(Adam::new(varmap, lr)?),
                None => None,
            },
            target_entropy: config.target_entropy.unwrap_or(-(act_dim as f32)),
            buffer: ReplayBuffer::new(config.buffer_size, obs_dim, act_dim),
            sample: ReplaySample::default(),
            nets,
            rng,
            num_timesteps: 0,
            grad_accumulator: 0.0,
            n_updates: 0,
            obs_dim,
            act_dim,
            config,
        })
    }

    /// Gradient steps taken so far.
    pub fn n_updates(&self) -> u64 {
        self.n_updates
    }

    /// Transitions in the replay buffer.
    pub fn replay_len(&self) -> usize {
        self.buffer.len()
    }

    /// The entropy coefficient α now.
    pub fn ent_coef(&self) -> Result<f32> {
        Ok(match &self.nets.log_alpha {
            Some((_, log_alpha)) => log_alpha.as_tensor().exp()?.to_vec1::<f32>()?[0],
            // No log α exactly when the coefficient is fixed.
            None => self.config.ent_coef.unwrap_or(0.0),
        })
    }

    /// `rows × act_dim` standard normal noise from the learner's stream (not candle's unseeded
    /// one), so a seeded run is reproducible.
    fn noise(&mut self, rows: usize) -> Result<Tensor> {
        Ok(standard_normal_tensor(&mut self.rng, rows, self.act_dim)?)
    }

    /// One gradient step of the critics, the actor and α on a minibatch from the replay buffer.
    fn gradient_step(&mut self) -> Result<StepStats> {
        let (b, od, ad) = (self.config.batch_size, self.obs_dim, self.act_dim);
        let dev = &Device::Cpu;
        self.buffer.sample_into(b, &mut self.rng, &mut self.sample);
        let s = &self.sample;
        let obs = Tensor::from_slice(&s.observations, (b, od), dev)?;
        let actions = Tensor::from_slice(&s.actions, (b, ad), dev)?;
        let rewards = Tensor::from_slice(&s.rewards, b, dev)?;
        let next_obs = Tensor::from_slice(&s.next_observations, (b, od), dev)?;
        let not_done = Tensor::from_slice(&s.dones, b, dev)?.affine(-1.0, 1.0)?;
        let alpha = self.ent_coef()? as f64;
        let gamma = self.config.gamma as f64;

        // Critic target from the next observations, with the current policy and α; no gradient.
        let next_eps = self.noise(b)?;
        let (next_actions, next_log_probs) = self
            .nets
            .policy
            .actor
            .distribution(&next_obs)?
            .sample(&next_eps)?;
        let next_q = (self
            .nets
            .policy
            .critic_target
            .min_q(&next_obs, &next_actions)?
            - (next_log_probs * alpha)?)?;
        let target = (rewards + ((not_done * next_q)? * gamma)?)?.detach();

        let (q1, q2) = self.nets.policy.critic.q(&obs, &actions)?;
        let critic_loss =
            (((q1 - &target)?.sqr()?.mean_all()? + (q2 - &target)?.sqr()?.mean_all()?)? * 0.5)?;
        self.critic_opt.backward_step(&critic_loss, 0.0)?;

        // Actor against the critics just updated (as CleanRL and SB3 do). The backward pass also
        // reaches the critics' variables, but only the actor's optimiser steps.
        let eps = self.noise(b)?;
        let (pi_actions, log_probs) = self.nets.policy.actor.distribution(&obs)?.sample(&eps)?;
        let q_pi = self.nets.policy.critic.min_q(&obs, &pi_actions)?;
        let actor_loss = ((&log_probs * alpha)? - q_pi)?.mean_all()?;
        self.actor_opt.backward_step(&actor_loss, 0.0)?;

        // α: −mean(log α · (log π + H̄)) = −log α · (mean log π + H̄), with log π fixed.
        let mut ent_coef_loss = 0.0;
        if let (Some(opt), Some((_, log_alpha))) = (&mut self.alpha_opt, &self.nets.log_alpha) {
            let mean_log_prob = log_probs.mean_all()?.to_scalar::<f32>()?;
            let loss = (log_alpha.as_tensor() * -((mean_log_prob + self.target_entropy) as f64))?
                .sum_all()?;
            opt.backward_step(&loss, 0.0)?;
            ent_coef_loss = loss.to_scalar::<f32>()?;
        }

        self.nets.policy.soft_update(self.config.tau)?;
        self.n_updates += 1;
        Ok(StepStats {
            actor_loss: actor_loss.to_scalar()?,
            critic_loss: critic_loss.to_scalar()?,
            ent_coef: alpha as f32,
            ent_coef_loss,
        })
    }

    /// Errors when `venv` is not the environment this learner was built for, or acts outside
    /// the `[-1, 1]` box the tanh policy covers.
    fn check_env<V: VectorEnv>(&self, venv: &V) -> Result<()> {
        if venv.obs_dim() != self.obs_dim || venv.act_dim() != self.act_dim {
            return Err(RlError::Other(format!(
                "SAC was built for {} observation and {} action values, the environments have \
                 {} and {}",
                self.obs_dim,
                self.act_dim,
                venv.obs_dim(),
                venv.act_dim()
            )));
        }
        let space = venv.action_space();
        if space.low.iter().any(|&l| l != -1.0) || space.high.iter().any(|&h| h != 1.0) {
            return Err(RlError::Other(format!(
                "SAC's actions lie in [-1, 1], the environments' action space is {:?} to {:?}; \
                 wrap them in RescaleAction",
                space.low, space.high
            )));
        }
        Ok(())
    }
}

/// The entries of `state` under `prefix`, without it.
fn unprefixed(state: &TensorMap, prefix: &str) -> TensorMap {
    state
        .iter()
        .filter_map(|(k, v)| Some((k.strip_prefix(prefix)?.to_string(), v.clone())))
        .collect()
}

/// One number of the training state.
fn state_scalar(state: &TensorMap, key: &str) -> Result<f64> {
    let t = state
        .get(key)
        .ok_or_else(|| RlError::Model(format!("the training state lacks `{key}`")))?;
    match t
        .to_dtype(DType::F64)
        .and_then(|t| t.flatten_all()?.to_vec1::<f64>())
    {
        Ok(v) if v.len() == 1 && v[0].is_finite() && v[0] >= 0.0 => Ok(v[0]),
        _ => Err(RlError::Model(format!(
            "`{key}` must hold one non-negative number"
        ))),
    }
}

impl Algorithm for Sac {
    fn name(&self) -> &'static str {
        "sac"
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
        _progress_remaining: f64,
        on_step: &mut dyn FnMut(&VecStep<'_>),
    ) -> Result<Vec<(&'static str, f32)>> {
        self.check_env(venv)?;
        let (n, od, ad) = (venv.num_envs(), self.obs_dim, self.act_dim);
        let obs = venv.observations().to_vec();
        let actions: Vec<f32> = if self.num_timesteps < self.config.learning_starts {
            (0..n * ad)
                .map(|_| self.rng.random_range(-1.0..=1.0))
                .collect()
        } else {
            self.predict(&obs, false)?
        };
        let step = venv.step(&actions)?;
        on_step(&step);
        for i in 0..n {
            // An ended episode's row already belongs to the next episode: store its real last
            // observation, which a truncation bootstraps from.
            let next_obs = step.terminal_observation(i).unwrap_or(step.obs(i));
            self.buffer.push(
                &obs[i * od..(i + 1) * od],
                &actions[i * ad..(i + 1) * ad],
                step.rewards[i],
                next_obs,
                step.terminated[i],
            );
        }
        self.num_timesteps += n as u64;
        if self.num_timesteps < self.config.learning_starts {
            return Ok(Vec::new());
        }

        self.grad_accumulator += self.config.utd_ratio as f64 * n as f64;
        let steps = self.grad_accumulator.floor();
        self.grad_accumulator -= steps;
        if steps < 1.0 {
            return Ok(Vec::new());
        }
        let mut sum = StepStats::default();
        for _ in 0..steps as u64 {
            let s = self.gradient_step()?;
            sum.actor_loss += s.actor_loss;
            sum.critic_loss += s.critic_loss;
            sum.ent_coef += s.ent_coef;
            sum.ent_coef_loss += s.ent_coef_loss;
        }
        let k = steps as f32;
        let mut stats = vec![
            ("train/actor_loss", sum.actor_loss / k),
            ("train/critic_loss", sum.critic_loss / k),
            ("train/ent_coef", sum.ent_coef / k),
        ];
        if self.alpha_opt.is_some() {
            stats.push(("train/ent_coef_loss", sum.ent_coef_loss / k));
        }
        stats.push(("train/learning_rate", self.config.learning_rate as f32));
        Ok(stats)
    }

    fn predict(&mut self, obs: &[f32], deterministic: bool) -> Result<Vec<f32>> {
        self.nets
            .policy
            .actor
            .predict(obs, deterministic, &mut self.rng)
    }

    fn weights(&self) -> Result<TensorMap> {
        Ok(self.nets.weights())
    }

    fn load_weights(&mut self, weights: &TensorMap) -> Result<()> {
        self.nets
            .load_weights(weights, self.obs_dim, self.act_dim, &self.config)
    }

    fn training_state(&self) -> Result<TensorMap> {
        let dev = &Device::Cpu;
        let mut state = TensorMap::new();
        let mut optimizers = vec![
            ("actor_opt.", &self.actor_opt),
            ("critic_opt.", &self.critic_opt),
        ];
        if let Some(opt) = &self.alpha_opt {
            optimizers.push(("alpha_opt.", opt));
        }
        for (prefix, opt) in optimizers {
            state.extend(
                opt.state()?
                    .into_iter()
                    .map(|(k, v)| (format!("{prefix}{k}"), v)),
            );
        }
        state.extend(rng_state(&self.rng, "sac.")?);
        state.insert(
            "sac.grad_accumulator".into(),
            Tensor::new(&[self.grad_accumulator], dev)?,
        );
        state.insert(
            "sac.n_updates".into(),
            Tensor::new(&[self.n_updates as f64], dev)?,
        );
        if self.config.save_replay_buffer {
            state.extend(self.buffer.state("sac.replay.")?);
        }
        Ok(state)
    }

    fn load_training_state(&mut self, state: &TensorMap) -> Result<()> {
        // Everything is read into new values first, so a bad state changes nothing.
        let lr = self.config.learning_rate;
        let load_opt = |varmap: &VarMap, prefix: &str| -> Result<Adam> {
            let mut opt = Adam::new(varmap, lr)?;
            opt.load_state(&unprefixed(state, prefix))
                .map_err(|e| RlError::Model(format!("{e} (under `{prefix}`)")))?;
            Ok(opt)
        };
        let actor_opt = load_opt(&self.nets.policy.actor.varmap, "actor_opt.")?;
        let critic_opt = load_opt(&self.nets.policy.critic.varmap, "critic_opt.")?;
        let alpha_opt = match &self.nets.log_alpha {
            Some((varmap, _)) => Some(load_opt(varmap, "alpha_opt.")?),
            None => None,
        };
        let rng = rng_from_state(state, "sac.")?;
        let grad_accumulator = state_scalar(state, "sac.grad_accumulator")?;
        let n_updates = state_scalar(state, "sac.n_updates")? as u64;
        // A run that keeps its buffer in checkpoints needs it back; otherwise a state without
        // one resumes with the buffer as it is (empty in a fresh learner, as in SB3).
        if self.config.save_replay_buffer || state.contains_key("sac.replay.rewards") {
            self.buffer
                .load_state(state, "sac.replay.")
                .map_err(RlError::Model)?;
        }
        self.actor_opt = actor_opt;
        self.critic_opt = critic_opt;
        self.alpha_opt = alpha_opt;
        self.rng = rng;
        self.grad_accumulator = grad_accumulator;
        self.n_updates = n_updates;
        Ok(())
    }

    fn rng_mut(&mut self) -> &mut ChaCha8Rng {
        &mut self.rng
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::standard_normal;
    use fairgrasp_env::tasks::classic::Pendulum;
    use fairgrasp_env::wrappers::RescaleAction;
    use fairgrasp_env::{Env, VecEnv};
    use std::collections::HashMap;

    fn small_config() -> SacConfig {
        SacConfig {
            buffer_size: 1_000,
            learning_starts: 40,
            batch_size: 16,
            net_arch: vec![16, 16],
            // Fractional steps per iteration with two envs, so the accumulator matters.
            utd_ratio: 0.75,
            ..SacConfig::default()
        }
    }

    fn pendulums(n: usize, seed: u64) -> VecEnv<RescaleAction<Pendulum>> {
        let envs = (0..n)
            .map(|_| RescaleAction::new(Pendulum::new()).unwrap())
            .collect();
        let mut venv = VecEnv::new(envs, 1).unwrap();
        venv.reset(Some(seed)).unwrap();
        venv
    }

    /// Deep copies of tensors (a variable's tensor shares its storage, which training changes).
    fn snapshot(map: &TensorMap) -> HashMap<String, Vec<f32>> {
        map.iter()
            .map(|(k, t)| {
                let values = t.flatten_all().unwrap().to_dtype(DType::F32).unwrap();
                (k.clone(), values.to_vec1().unwrap())
            })
            .collect()
    }

    #[test]
    fn polyak_update_moves_targets_by_tau() {
        let sac = Sac::new(small_config(), 3, 1, 2, 0).unwrap();
        // Make the online critics differ from their targets.
        for (online, _) in &sac.nets.policy.target_pairs {
            online
                .set(&online.as_tensor().randn_like(0.0, 1.0).unwrap())
                .unwrap();
        }
        let before = snapshot(&varmap_tensors(&sac.nets.policy.critic_target.varmap, ""));
        let online = snapshot(&varmap_tensors(&sac.nets.policy.critic.varmap, ""));
        let tau = 0.25;
        sac.nets.policy.soft_update(tau).unwrap();
        let after = snapshot(&varmap_tensors(&sac.nets.policy.critic_target.varmap, ""));
        assert_eq!(after.len(), online.len());
        for (name, t_after) in &after {
            let o = &online[&name.replacen("critic_target.", "critic.", 1)];
            for (k, (&a, &b)) in t_after.iter().zip(&before[name]).enumerate() {
                let want = (1.0 - tau) * b + tau * o[k];
                assert!(
                    (a - want).abs() <= 1e-6 * (1.0 + want.abs()),
                    "{name}[{k}]: {a} vs {want}"
                );
                assert!(b == o[k] || a != b, "{name}[{k}] did not move");
            }
        }
        // The online critics are untouched.
        assert_eq!(
            online,
            snapshot(&varmap_tensors(&sac.nets.policy.critic.varmap, ""))
        );
    }

    #[test]
    fn a_seed_fixes_the_initial_networks() {
        let a = snapshot(
            &Sac::new(small_config(), 3, 1, 2, 5)
                .unwrap()
                .weights()
                .unwrap(),
        );
        let b = snapshot(
            &Sac::new(small_config(), 3, 1, 2, 5)
                .unwrap()
                .weights()
                .unwrap(),
        );
        let c = snapshot(
            &Sac::new(small_config(), 3, 1, 2, 6)
                .unwrap()
                .weights()
                .unwrap(),
        );
        assert_eq!(a, b);
        assert_ne!(a["actor.l0.weight"], c["actor.l0.weight"]);
        // The targets start as copies of the critics.
        assert_eq!(a["critic.qf2.l1.weight"], a["critic_target.qf2.l1.weight"]);
        assert_eq!(a["log_alpha"], [0.0]);
    }

    #[test]
    fn gradient_steps_follow_the_utd_ratio() {
        // 0.1 steps per transition with 4 envs: 0.4 per iteration, so 2 steps every 5.
        let config = SacConfig {
            utd_ratio: 0.1,
            learning_starts: 0,
            ..small_config()
        };
        let mut sac = Sac::new(config, 3, 1, 4, 0).unwrap();
        let mut venv = pendulums(4, 0);
        let mut learnt = 0;
        for _ in 0..20 {
            let stats = sac.learn_iteration(&mut venv, 1.0, &mut |_| {}).unwrap();
            if !stats.is_empty() {
                learnt += 1;
                let names: Vec<&str> = stats.iter().map(|s| s.0).collect();
                assert_eq!(
                    names,
                    [
                        "train/actor_loss",
                        "train/critic_loss",
                        "train/ent_coef",
                        "train/ent_coef_loss",
                        "train/learning_rate"
                    ]
                );
                assert!(stats.iter().all(|s| s.1.is_finite()), "{stats:?}");
            }
        }
        assert_eq!((sac.num_timesteps(), sac.replay_len()), (80, 80));
        assert_eq!((sac.n_updates(), learnt), (8, 8));
    }

    #[test]
    fn random_actions_and_no_learning_before_learning_starts() {
        let mut sac = Sac::new(small_config(), 3, 1, 2, 0).unwrap();
        let mut venv = pendulums(2, 0);
        let initial = snapshot(&sac.weights().unwrap());
        for _ in 0..19 {
            assert!(
                sac.learn_iteration(&mut venv, 1.0, &mut |_| {})
                    .unwrap()
                    .is_empty()
            );
        }
        assert_eq!(sac.n_updates(), 0);
        assert_eq!(snapshot(&sac.weights().unwrap()), initial);
        // The random actions cover [-1, 1], unlike the initial policy (σ ≈ 0.22).
        let stored = snapshot(&sac.buffer.state("").unwrap());
        let actions = &stored["actions"];
        assert_eq!(actions.len(), 38);
        assert!(actions.iter().all(|a| (-1.0..=1.0).contains(a)));
        assert!(actions.iter().any(|&a| a > 0.8) && actions.iter().any(|&a| a < -0.8));
        // The 40th step starts learning.
        assert!(
            !sac.learn_iteration(&mut venv, 1.0, &mut |_| {})
                .unwrap()
                .is_empty()
        );
        assert_eq!(sac.n_updates(), 1);
    }

    #[test]
    fn truncations_store_the_final_observation_and_bootstrap() {
        let mut sac = Sac::new(small_config(), 3, 1, 1, 0).unwrap();
        let mut venv = pendulums(1, 3);
        let mut last = Vec::new();
        for _ in 0..Pendulum::MAX_STEPS {
            let before = venv.observations().to_vec();
            sac.learn_iteration(&mut venv, 1.0, &mut |step| {
                if let Some(obs) = step.terminal_observation(0) {
                    last = obs.to_vec();
                }
            })
            .unwrap();
            assert_ne!(before, venv.observations());
        }
        let i = Pendulum::MAX_STEPS as usize - 1;
        let stored = snapshot(&sac.buffer.state("").unwrap());
        assert_eq!(stored["next_observations"][3 * i..3 * i + 3], last);
        assert_ne!(venv.observations(), last.as_slice());
        assert!(stored["dones"].iter().all(|&d| d == 0.0));
    }

    #[test]
    fn training_state_round_trip_continues_bit_exactly() {
        let mut a = Sac::new(small_config(), 3, 1, 2, 1).unwrap();
        let mut venv = pendulums(2, 1);
        for _ in 0..46 {
            a.learn_iteration(&mut venv, 1.0, &mut |_| {}).unwrap();
        }
        assert!(a.n_updates() > 20 && a.grad_accumulator != 0.0);
        let weights = a.weights().unwrap();
        let state = a.training_state().unwrap();

        // Learners from another seed: one gets weights and state, one only the weights.
        let mut b = Sac::new(small_config(), 3, 1, 2, 99).unwrap();
        b.load_weights(&weights).unwrap();
        b.load_training_state(&state).unwrap();
        b.set_num_timesteps(a.num_timesteps());
        let mut c = Sac::new(small_config(), 3, 1, 2, 99).unwrap();
        c.load_weights(&weights).unwrap();
        c.set_num_timesteps(a.num_timesteps());
        assert_eq!(
            snapshot(&a.weights().unwrap()),
            snapshot(&b.weights().unwrap())
        );

        let run = |sac: &mut Sac| {
            let mut venv = pendulums(2, 50);
            let mut stats = Vec::new();
            for _ in 0..6 {
                stats.push(sac.learn_iteration(&mut venv, 1.0, &mut |_| {}).unwrap());
            }
            let obs = [0.5f32, -0.3, 1.0, 0.1, 0.9, -2.0];
            let actions = sac.predict(&obs, false).unwrap();
            (
                stats,
                actions,
                snapshot(&sac.weights().unwrap()),
                sac.n_updates(),
            )
        };
        let (ra, rb, rc) = (run(&mut a), run(&mut b), run(&mut c));
        assert!(!ra.0.iter().all(|s| s.is_empty()));
        assert_eq!(ra.0, rb.0);
        assert_eq!(ra.1, rb.1);
        assert_eq!(ra.2, rb.2);
        assert_eq!(ra.3, rb.3);
        // Without the training state (optimiser moments, replay buffer, random stream) the runs part.
        assert_ne!(ra.0, rc.0);
        assert_ne!(ra.1, rc.1);

        // A missing piece is an error that names it, and changes nothing.
        for key in [
            "critic_opt.adam.v.critic.qf1.l0.bias",
            "sac.rng.seed",
            "sac.replay.actions",
            "sac.grad_accumulator",
        ] {
            let mut broken = state.clone();
            broken.remove(key).unwrap();
            let err = b.load_training_state(&broken).unwrap_err().to_string();
            assert!(
                err.contains(&key[key.find("adam").unwrap_or(0)..]),
                "{key}: {err}"
            );
        }
    }

    #[test]
    fn mismatched_weights_are_rejected_and_change_nothing() {
        let mut a = Sac::new(small_config(), 3, 1, 2, 1).unwrap();
        let before = snapshot(&a.weights().unwrap());
        // Valid new values for the earlier groups (actor, critic), a wrong shape in a later one.
        let mut other = Sac::new(small_config(), 3, 1, 2, 2)
            .unwrap()
            .weights()
            .unwrap();
        let bad = "critic_target.qf2.l1.weight";
        other.insert(
            bad.into(),
            Tensor::zeros((16, 15), DType::F32, &Device::Cpu).unwrap(),
        );
        let err = a.load_weights(&other).unwrap_err().to_string();
        assert!(err.contains(bad), "{err}");
        assert_eq!(snapshot(&a.weights().unwrap()), before);

        let mut missing = a.weights().unwrap();
        missing.remove("log_alpha");
        let err = a.load_weights(&missing).unwrap_err().to_string();
        assert!(err.contains("`log_alpha`"), "{err}");
        let mut extra = a.weights().unwrap();
        extra.insert(
            "critic.qf3.l0.weight".into(),
            Tensor::zeros(1, DType::F32, &Device::Cpu).unwrap(),
        );
        let err = a.load_weights(&extra).unwrap_err().to_string();
        assert!(err.contains("critic.qf3.l0.weight"), "{err}");
        // A fixed entropy coefficient has no log α to load.
        let mut fixed = Sac::new(
            SacConfig {
                ent_coef: Some(0.1),
                ..small_config()
            },
            3,
            1,
            2,
            1,
        )
        .unwrap();
        let err = fixed
            .load_weights(&a.weights().unwrap())
            .unwrap_err()
            .to_string();
        assert!(err.contains("log_alpha"), "{err}");
        assert_eq!(snapshot(&a.weights().unwrap()), before);
    }

    #[test]
    fn validate_names_each_bad_setting() {
        let cases: Vec<(&str, SacConfig)> = vec![
            (
                "learning_rate",
                SacConfig {
                    learning_rate: 0.0,
                    ..SacConfig::default()
                },
            ),
            (
                "buffer_size",
                SacConfig {
                    buffer_size: 0,
                    ..SacConfig::default()
                },
            ),
            (
                "batch_size",
                SacConfig {
                    batch_size: 0,
                    ..SacConfig::default()
                },
            ),
            (
                "tau",
                SacConfig {
                    tau: 1.5,
                    ..SacConfig::default()
                },
            ),
            (
                "gamma",
                SacConfig {
                    gamma: -0.1,
                    ..SacConfig::default()
                },
            ),
            (
                "utd_ratio",
                SacConfig {
                    utd_ratio: 0.0,
                    ..SacConfig::default()
                },
            ),
            (
                "ent_coef",
                SacConfig {
                    ent_coef: Some(f32::NAN),
                    ..SacConfig::default()
                },
            ),
            (
                "ent_coef_init",
                SacConfig {
                    ent_coef_init: 0.0,
                    ..SacConfig::default()
                },
            ),
            (
                "target_entropy",
                SacConfig {
                    target_entropy: Some(f32::INFINITY),
                    ..SacConfig::default()
                },
            ),
            (
                "net_arch",
                SacConfig {
                    net_arch: vec![64, 0],
                    ..SacConfig::default()
                },
            ),
        ];
        validate(&SacConfig::default(), 4).unwrap();
        for (key, config) in cases {
            match validate(&config, 4) {
                Err(RlError::Config { key: k, .. }) => assert_eq!(k, format!("sac.{key}")),
                other => panic!("{key}: {other:?}"),
            }
        }
    }

    #[test]
    fn environments_outside_the_unit_box_are_refused() {
        let mut sac = Sac::new(small_config(), 3, 1, 1, 0).unwrap();
        let mut venv = VecEnv::new(vec![Pendulum::new()], 1).unwrap();
        venv.reset(Some(0)).unwrap();
        let err = sac
            .learn_iteration(&mut venv, 1.0, &mut |_| {})
            .unwrap_err();
        assert!(err.to_string().contains("RescaleAction"), "{err}");
        assert_eq!(Pendulum::new().action_space().high, [2.0]);
    }

    /// Gradient steps per second at the grasping task's sizes and at the Pendulum test's (run
    /// with `--ignored` in release; `RAYON_NUM_THREADS` sets candle's threads).
    #[test]
    #[ignore]
    fn gradient_step_throughput() {
        for (obs_dim, act_dim, net_arch) in [(40, 5, vec![256, 256]), (3, 1, vec![64, 64])] {
            let config = SacConfig {
                net_arch: net_arch.clone(),
                ..SacConfig::default()
            };
            let mut sac = Sac::new(config, obs_dim, act_dim, 1, 0).unwrap();
            let mut rng = ChaCha8Rng::seed_from_u64(0);
            for _ in 0..10_000 {
                let obs: Vec<f32> = (0..obs_dim).map(|_| standard_normal(&mut rng)).collect();
                let action: Vec<f32> = (0..act_dim).map(|_| rng.random_range(-1.0..1.0)).collect();
                sac.buffer.push(&obs, &action, rng.random(), &obs, false);
            }
            for _ in 0..10 {
                sac.gradient_step().unwrap();
            }
            let n = 200;
            let start = std::time::Instant::now();
            for _ in 0..n {
                sac.gradient_step().unwrap();
            }
            let secs = start.elapsed().as_secs_f64();
            eprintln!(
                "batch 256, {net_arch:?} nets, {obs_dim} → {act_dim}: {:.1} gradient steps/s",
                n as f64 / secs
            );
        }
    }
}
