//! Soft Actor-Critic (Haarnoja et al. 2018) with twin critics and a learnt entropy coefficient,
//! read top to bottom like CleanRL's `sac_continuous_action.py`, with SB3's SAC semantics.
//!
//! Per iteration ([`crate::off_policy`], shared with TD3): one step of every environment
//! (uniformly random actions for the first `learning_starts` steps), its transitions into the
//! replay buffer, then on average `utd_ratio` gradient steps per transition. A gradient step, on
//! a minibatch `(s, a, r, s', d)`:
//! - critics: `y = r + γ (1 − d) (min Q'(s', a') − α log π(a'|s'))`, `a' ~ π(·|s')`, minimise
//!   `½ Σᵢ (Qᵢ(s, a) − y)²`;
//! - actor: minimise `α log π(ã|s) − min Q(s, ã)`, `ã ~ π(·|s)` reparameterised;
//! - entropy coefficient (when learnt): minimise `−log α · (log π(ã|s) + H̄)`;
//! - target critics: `Q' ← (1 − τ) Q' + τ Q`.
//!
//! `d` is termination only: a truncated episode is bootstrapped from its real last observation.
//! The policy is a tanh-squashed Gaussian, so actions lie in `[-1, 1]`: the environments must
//! act in that box (the driver wraps them in `RescaleAction`).

use crate::algorithm::{TensorMap, load_grouped, varmap_tensors};
use crate::buffers::ReplayBuffer;
use crate::error::{ConfigSection, Result, RlError};
use crate::nn::{Activation, Adam};
use crate::off_policy::{
    Batch, OffPolicy, OffPolicyCore, check_shared_settings, load_adam, loop_settings,
};
use crate::policies::ActorNet;
use crate::policies::features::FeaturesConfig;
use crate::policies::net_config::NetConfig;
use crate::policies::squashed_gaussian::{SquashedGaussianActor, SquashedGaussianPolicy};
use candle_core::{DType, Device, Var};
use candle_nn::{VarBuilder, VarMap};
use serde::{Deserialize, Serialize};

/// SAC hyperparameters (SB3's names and defaults where they exist).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SacConfig {
    /// Adam's step size for every network (SB3's `learning_rate`); positive.
    pub learning_rate: f64,
    /// Replay buffer capacity (transitions).
    pub buffer_size: usize,
    /// Environment steps (all envs together) of uniformly random actions before learning.
    pub learning_starts: u64,
    /// Transitions per minibatch (SB3's `batch_size`); at least 1.
    pub batch_size: usize,
    /// Polyak coefficient of the target critics.
    pub tau: f32,
    /// Discount factor, in [0, 1].
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
    /// The activation after each hidden layer.
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

impl SacConfig {
    /// The shape of the networks (the policy's part of these settings).
    pub fn net(&self) -> NetConfig {
        NetConfig {
            net_arch: self.net_arch.clone(),
            activation: self.activation,
            features: self.features.clone(),
        }
    }
}

pub(crate) fn validate(c: &SacConfig, _n_envs: usize) -> Result<()> {
    let section = ConfigSection("sac");
    let settings = loop_settings!(c);
    check_shared_settings(&section, c.learning_rate, &settings, c.tau, c.gamma)?;
    if let Some(v) = c.ent_coef {
        section.non_negative("ent_coef", v)?;
    }
    // Taken as a logarithm, so it must be positive even where a fixed `ent_coef` overrides it.
    section.positive("ent_coef_init", c.ent_coef_init)?;
    if let Some(v) = c.target_entropy
        && !v.is_finite()
    {
        return section.bad("target_entropy", format!("must be finite, got {v}"));
    }
    section.net_arch(&c.net_arch)
}

/// Every network of the learner: the policy's and log α. Variable names carry their group's
/// prefix (`actor.`, `critic.`, `critic_target.`, `log_alpha`), so saved weights and errors
/// name tensors unambiguously.
pub(crate) struct Networks {
    pub(crate) policy: SquashedGaussianPolicy,
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
            policy: SquashedGaussianPolicy::zeroed(obs_dim, act_dim, &config.net())?,
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
        let scratch = Networks::zeroed(obs_dim, act_dim, config)?;
        load_grouped(&self.groups(), &scratch.groups(), weights)
    }

    /// The actor alone (for acting).
    pub(crate) fn into_actor(self) -> SquashedGaussianActor {
        self.policy.actor
    }
}

/// The acting network of a saved model: its actor, once every tensor of `weights` was checked
/// against the whole learner's networks.
pub(crate) fn load_actor(
    weights: &TensorMap,
    obs_dim: usize,
    act_dim: usize,
    config: &SacConfig,
) -> Result<SquashedGaussianActor> {
    let nets = Networks::zeroed(obs_dim, act_dim, config)?;
    nets.load_weights(weights, obs_dim, act_dim, config)?;
    Ok(nets.into_actor())
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

/// The SAC learner: networks and optimisers on the shared off-policy core (replay buffer,
/// random stream, learn loop).
pub struct Sac {
    /// The hyperparameters.
    pub config: SacConfig,
    nets: Networks,
    actor_opt: Adam,
    critic_opt: Adam,
    /// The optimiser of log α, when it is learnt.
    alpha_opt: Option<Adam>,
    target_entropy: f32,
    core: OffPolicyCore,
}

impl Sac {
    /// A learner for environments with `obs_dim` observation and `act_dim` action values
    /// (`n_envs` of them), its networks and stream seeded with `seed`; fails on an invalid
    /// configuration.
    pub fn new(
        config: SacConfig,
        obs_dim: usize,
        act_dim: usize,
        n_envs: usize,
        seed: u64,
    ) -> Result<Self> {
        validate(&config, n_envs)?;
        let mut core = OffPolicyCore::new("sac", loop_settings!(config), obs_dim, act_dim, seed)?;
        let nets = Networks::zeroed(obs_dim, act_dim, &config)?;
        nets.policy.init_weights(&mut core.rng)?;
        let lr = config.learning_rate;
        Ok(Self {
            actor_opt: Adam::new(&nets.policy.actor.varmap, lr)?,
            critic_opt: Adam::new(&nets.policy.critics.online.varmap, lr)?,
            alpha_opt: match &nets.log_alpha {
                Some((varmap, _)) => Some(Adam::new(varmap, lr)?),
                None => None,
            },
            target_entropy: config.target_entropy.unwrap_or(-(act_dim as f32)),
            nets,
            core,
            config,
        })
    }

    /// Gradient steps taken so far.
    pub fn n_updates(&self) -> u64 {
        self.core.n_updates
    }

    /// Transitions in the replay buffer.
    pub fn replay_len(&self) -> usize {
        self.core.buffer.len()
    }

    /// The replay buffer (to fill it directly, as `fairgrasp bench sac` does).
    pub fn replay_buffer_mut(&mut self) -> &mut ReplayBuffer {
        &mut self.core.buffer
    }

    /// `gradient_steps` gradient steps on minibatches from the replay buffer (SB3's
    /// `SAC.train`); returns the `train/*` means to log. The buffer must not be empty.
    pub fn train(&mut self, gradient_steps: u64) -> Result<Vec<(&'static str, f32)>> {
        let mut sum = StepStats::default();
        for _ in 0..gradient_steps {
            let s = self.gradient_step()?;
            sum.actor_loss += s.actor_loss;
            sum.critic_loss += s.critic_loss;
            sum.ent_coef += s.ent_coef;
            sum.ent_coef_loss += s.ent_coef_loss;
        }
        let k = gradient_steps.max(1) as f32;
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

    /// The entropy coefficient α now.
    pub fn ent_coef(&self) -> Result<f32> {
        Ok(match &self.nets.log_alpha {
            Some((_, log_alpha)) => log_alpha.as_tensor().exp()?.to_vec1::<f32>()?[0],
            // No log α exactly when the coefficient is fixed.
            None => self.config.ent_coef.unwrap_or(0.0),
        })
    }

    /// One gradient step of the critics, the actor and α on a minibatch from the replay buffer.
    fn gradient_step(&mut self) -> Result<StepStats> {
        let b = self.config.batch_size;
        let Batch {
            obs,
            actions,
            rewards,
            next_obs,
            not_done,
        } = self.core.sample_batch()?;
        let alpha = self.ent_coef()? as f64;
        let gamma = self.config.gamma as f64;
        let policy = &self.nets.policy;

        // Critic target from the next observations, with the current policy and α; no gradient.
        let next_eps = self.core.noise(b)?;
        let (next_actions, next_log_probs) =
            policy.actor.distribution(&next_obs)?.sample(&next_eps)?;
        let next_q =
            (policy.critics.target.min_q(&next_obs, &next_actions)? - (next_log_probs * alpha)?)?;
        let target = (rewards + ((not_done * next_q)? * gamma)?)?.detach();

        let (q1, q2) = policy.critics.online.q(&obs, &actions)?;
        let critic_loss =
            (((q1 - &target)?.sqr()?.mean_all()? + (q2 - &target)?.sqr()?.mean_all()?)? * 0.5)?;
        self.critic_opt.backward_step(&critic_loss, 0.0)?;

        // Actor against the critics just updated (as CleanRL and SB3 do), their weights held
        // constant: only the actor's optimiser steps.
        let eps = self.core.noise(b)?;
        let (pi_actions, log_probs) = policy.actor.distribution(&obs)?.sample(&eps)?;
        let q_pi = policy.critics.online.min_q_detached(&obs, &pi_actions)?;
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
        self.core.n_updates += 1;
        Ok(StepStats {
            actor_loss: actor_loss.to_scalar()?,
            critic_loss: critic_loss.to_scalar()?,
            ent_coef: alpha as f32,
            ent_coef_loss,
        })
    }
}

impl OffPolicy for Sac {
    const NAME: &'static str = "sac";
    /// Actor, critics and (when α is learnt) log α.
    type Optimizers = (Adam, Adam, Option<Adam>);

    fn core(&self) -> &OffPolicyCore {
        &self.core
    }

    fn actor_and_core(&mut self) -> (&dyn ActorNet, &mut OffPolicyCore) {
        (&self.nets.policy.actor, &mut self.core)
    }

    fn train(&mut self, gradient_steps: u64) -> Result<Vec<(&'static str, f32)>> {
        Sac::train(self, gradient_steps)
    }

    fn networks(&self) -> TensorMap {
        self.nets.weights()
    }

    fn load_networks(&mut self, weights: &TensorMap) -> Result<()> {
        let (od, ad) = (self.core.obs_dim, self.core.act_dim);
        self.nets.load_weights(weights, od, ad, &self.config)
    }

    fn optimizers(&self) -> Vec<(&'static str, &Adam)> {
        let mut optimizers = vec![
            ("actor_opt.", &self.actor_opt),
            ("critic_opt.", &self.critic_opt),
        ];
        if let Some(opt) = &self.alpha_opt {
            optimizers.push(("alpha_opt.", opt));
        }
        optimizers
    }

    fn read_optimizers(&self, state: &TensorMap) -> Result<Self::Optimizers> {
        let lr = self.config.learning_rate;
        let policy = &self.nets.policy;
        let actor_opt = load_adam(state, "actor_opt.", &policy.actor.varmap, lr)?;
        let critic_opt = load_adam(state, "critic_opt.", &policy.critics.online.varmap, lr)?;
        let alpha_opt = match &self.nets.log_alpha {
            Some((varmap, _)) => Some(load_adam(state, "alpha_opt.", varmap, lr)?),
            None => None,
        };
        Ok((actor_opt, critic_opt, alpha_opt))
    }

    fn set_optimizers(&mut self, (actor, critic, alpha): Self::Optimizers) {
        (self.actor_opt, self.critic_opt, self.alpha_opt) = (actor, critic, alpha);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithm::Algorithm;
    use crate::off_policy::test_support::{
        assert_training_state_resumes, assert_validate_names_keys, fill_replay, pendulums,
        snapshot, unit_box_error, weights_of,
    };
    use candle_core::Tensor;
    use fairgrasp_env::Env;
    use fairgrasp_env::VectorEnv;
    use fairgrasp_env::tasks::classic::Pendulum;

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

    #[test]
    fn polyak_update_moves_targets_by_tau() {
        let sac = Sac::new(small_config(), 3, 1, 2, 0).unwrap();
        // Make the online critics differ from their targets.
        for (online, _) in &sac.nets.policy.critics.pairs.0 {
            online
                .set(&online.as_tensor().randn_like(0.0, 1.0).unwrap())
                .unwrap();
        }
        let before = snapshot(&varmap_tensors(&sac.nets.policy.critics.target.varmap, ""));
        let online = snapshot(&varmap_tensors(&sac.nets.policy.critics.online.varmap, ""));
        let tau = 0.25;
        sac.nets.policy.soft_update(tau).unwrap();
        let after = snapshot(&varmap_tensors(&sac.nets.policy.critics.target.varmap, ""));
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
            snapshot(&varmap_tensors(&sac.nets.policy.critics.online.varmap, ""))
        );
    }

    #[test]
    fn a_seed_fixes_the_initial_networks() {
        let a = weights_of(&Sac::new(small_config(), 3, 1, 2, 5).unwrap());
        let b = weights_of(&Sac::new(small_config(), 3, 1, 2, 5).unwrap());
        let c = weights_of(&Sac::new(small_config(), 3, 1, 2, 6).unwrap());
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
        let initial = weights_of(&sac);
        for _ in 0..19 {
            assert!(
                sac.learn_iteration(&mut venv, 1.0, &mut |_| {})
                    .unwrap()
                    .is_empty()
            );
        }
        assert_eq!(sac.n_updates(), 0);
        assert_eq!(weights_of(&sac), initial);
        // The random actions cover [-1, 1], unlike the initial policy (σ ≈ 0.22).
        let stored = snapshot(&sac.core.buffer.state("").unwrap());
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
        let stored = snapshot(&sac.core.buffer.state("").unwrap());
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
        assert!(a.n_updates() > 20 && a.core.grad_accumulator != 0.0);
        assert_training_state_resumes(
            &mut a,
            || Sac::new(small_config(), 3, 1, 2, 99).unwrap(),
            Sac::n_updates,
            &[
                "critic_opt.adam.v.critic.qf1.l0.bias",
                "sac.rng.seed",
                "sac.replay.actions",
                "sac.grad_accumulator",
            ],
        );
    }

    #[test]
    fn mismatched_weights_are_rejected_and_change_nothing() {
        let mut a = Sac::new(small_config(), 3, 1, 2, 1).unwrap();
        let before = weights_of(&a);
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
        assert_eq!(weights_of(&a), before);

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
        assert_eq!(weights_of(&a), before);
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
        assert_validate_names_keys("sac", validate, &SacConfig::default(), cases);
    }

    #[test]
    fn environments_outside_the_unit_box_are_refused() {
        let mut sac = Sac::new(small_config(), 3, 1, 1, 0).unwrap();
        let err = unit_box_error(&mut sac);
        assert!(err.contains("RescaleAction"), "{err}");
        assert_eq!(Pendulum::new().action_space().high, [2.0]);
    }

    #[test]
    fn train_takes_the_gradient_steps_asked_for() {
        let mut sac = Sac::new(small_config(), 3, 1, 1, 0).unwrap();
        let err = sac.train(1).unwrap_err().to_string();
        assert!(err.contains("empty replay buffer"), "{err}");
        fill_replay(sac.replay_buffer_mut(), 50);
        let before = weights_of(&sac);
        let stats = sac.train(3).unwrap();
        assert_eq!(sac.n_updates(), 3);
        assert_eq!(stats[0].0, "train/actor_loss");
        assert!(stats.iter().all(|s| s.1.is_finite()), "{stats:?}");
        assert_ne!(weights_of(&sac), before);
    }
}
