//! Twin Delayed DDPG (Fujimoto et al. 2018), read top to bottom like CleanRL's
//! `td3_continuous_action.py`, with SB3's TD3 names and semantics.
//!
//! Per iteration ([`crate::off_policy`], shared with SAC): one step of every environment
//! (uniformly random actions for the first `learning_starts` steps, then the policy's with
//! N(0, `action_noise`²) added), its transitions into the replay buffer, then on average
//! `utd_ratio` gradient steps per transition. A gradient step, on a minibatch `(s, a, r, s', d)`:
//! - target policy smoothing: `a' = clip(μ'(s') + clip(ε, −c, c), −1, 1)`,
//!   `ε ~ N(0, target_policy_noise²)`, `c = target_noise_clip`;
//! - critics: `y = r + γ (1 − d) min Q'(s', a')`, minimise `Σᵢ mean (Qᵢ(s, a) − y)²`;
//! - every `policy_delay`-th step only: actor minimises `−mean Q₁(s, μ(s))`, then both targets
//!   move: `θ' ← (1 − τ) θ' + τ θ`.
//!
//! `d` is termination only: a truncated episode is bootstrapped from its real last observation.

use crate::algorithm::{TensorMap, load_grouped, varmap_tensors};
use crate::error::{ConfigSection, Result};
use crate::nn::{Activation, Adam};
use crate::off_policy::{
    Batch, OffPolicy, OffPolicyCore, check_shared_settings, load_adam, loop_settings,
};
use crate::policies::ActorNet;
use crate::policies::deterministic::{DeterministicActor, DeterministicPolicy};
use crate::policies::features::FeaturesConfig;
use crate::policies::net_config::NetConfig;
use candle_core::Tensor;
use serde::{Deserialize, Serialize};

/// TD3 hyperparameters (SB3's names; the paper's noise settings).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Td3Config {
    /// Adam's step size for every network (SB3's `learning_rate`); positive.
    pub learning_rate: f64,
    /// Replay buffer capacity (transitions).
    pub buffer_size: usize,
    /// Environment steps (all envs together) of uniformly random actions before learning.
    pub learning_starts: u64,
    /// Transitions per minibatch (SB3's `batch_size`); at least 1.
    pub batch_size: usize,
    /// Polyak coefficient of the targets.
    pub tau: f32,
    /// Discount factor, in [0, 1].
    pub gamma: f32,
    /// Gradient steps per environment transition (update-to-data ratio).
    pub utd_ratio: f32,
    /// The actor and the targets learn every this many critic steps.
    pub policy_delay: u32,
    /// σ of the noise added to the target policy's actions (target policy smoothing).
    pub target_policy_noise: f32,
    /// That noise is clipped to ± this.
    pub target_noise_clip: f32,
    /// σ of the Gaussian exploration noise added to the actions while collecting.
    pub action_noise: f32,
    /// Hidden layers of the actor and of each critic.
    pub net_arch: Vec<usize>,
    /// The activation after each hidden layer.
    pub activation: Activation,
    /// Save the replay buffer in checkpoints, so a resumed run keeps its experience.
    pub save_replay_buffer: bool,
    /// What the actor and the critics read (`kind = "flatten"`: the observation itself).
    pub features: FeaturesConfig,
}

impl Default for Td3Config {
    fn default() -> Self {
        Self {
            learning_rate: 1e-3,
            buffer_size: 1_000_000,
            learning_starts: 10_000,
            batch_size: 256,
            tau: 0.005,
            gamma: 0.99,
            utd_ratio: 1.0,
            policy_delay: 2,
            target_policy_noise: 0.2,
            target_noise_clip: 0.5,
            action_noise: 0.1,
            net_arch: vec![256, 256],
            activation: Activation::Relu,
            save_replay_buffer: true,
            features: FeaturesConfig::Flatten {},
        }
    }
}

impl Td3Config {
    /// The shape of the networks (the policy's part of these settings).
    pub fn net(&self) -> NetConfig {
        NetConfig {
            net_arch: self.net_arch.clone(),
            activation: self.activation,
            features: self.features.clone(),
        }
    }
}

pub(crate) fn validate(c: &Td3Config, _n_envs: usize) -> Result<()> {
    let section = ConfigSection("td3");
    let settings = loop_settings!(c);
    check_shared_settings(&section, c.learning_rate, &settings, c.tau, c.gamma)?;
    section.at_least_one("policy_delay", c.policy_delay as usize)?;
    section.non_negative("target_policy_noise", c.target_policy_noise)?;
    section.non_negative("target_noise_clip", c.target_noise_clip)?;
    section.non_negative("action_noise", c.action_noise)?;
    section.net_arch(&c.net_arch)
}

/// The acting network of a saved model: builds the networks, loads `weights` (errors name the
/// tensor at fault) and returns the actor.
pub(crate) fn load_actor(
    weights: &TensorMap,
    obs_dim: usize,
    act_dim: usize,
    config: &Td3Config,
) -> Result<DeterministicActor> {
    let policy = DeterministicPolicy::zeroed(obs_dim, act_dim, &config.net(), config.action_noise)?;
    let scratch =
        DeterministicPolicy::zeroed(obs_dim, act_dim, &config.net(), config.action_noise)?;
    load_grouped(&policy.groups(), &scratch.groups(), weights)?;
    Ok(policy.actor)
}

/// The TD3 learner: networks and optimisers on the shared off-policy core (replay buffer,
/// random stream, learn loop).
pub struct Td3 {
    /// The hyperparameters.
    pub config: Td3Config,
    policy: DeterministicPolicy,
    actor_opt: Adam,
    critic_opt: Adam,
    core: OffPolicyCore,
}

impl Td3 {
    /// A learner for environments with `obs_dim` observation and `act_dim` action values
    /// (`n_envs` of them), its networks and stream seeded with `seed`; fails on an invalid
    /// configuration.
    pub fn new(
        config: Td3Config,
        obs_dim: usize,
        act_dim: usize,
        n_envs: usize,
        seed: u64,
    ) -> Result<Self> {
        validate(&config, n_envs)?;
        let mut core = OffPolicyCore::new("td3", loop_settings!(config), obs_dim, act_dim, seed)?;
        let policy =
            DeterministicPolicy::zeroed(obs_dim, act_dim, &config.net(), config.action_noise)?;
        policy.init_weights(&mut core.rng)?;
        let lr = config.learning_rate;
        Ok(Self {
            actor_opt: Adam::new(&policy.actor.varmap, lr)?,
            critic_opt: Adam::new(&policy.critics.online.varmap, lr)?,
            policy,
            core,
            config,
        })
    }

    /// Gradient steps (critic updates) taken so far.
    pub fn n_updates(&self) -> u64 {
        self.core.n_updates
    }

    /// Transitions in the replay buffer.
    pub fn replay_len(&self) -> usize {
        self.core.buffer.len()
    }

    /// `gradient_steps` gradient steps on minibatches from the replay buffer (SB3's
    /// `TD3.train`); returns the `train/*` means to log (`actor_loss` over the steps that
    /// updated the actor, if any did).
    pub fn train(&mut self, gradient_steps: u64) -> Result<Vec<(&'static str, f32)>> {
        let (mut critic_sum, mut actor_sum, mut actor_steps) = (0.0, 0.0, 0u32);
        for _ in 0..gradient_steps {
            let (critic_loss, actor_loss) = self.gradient_step()?;
            critic_sum += critic_loss;
            if let Some(loss) = actor_loss {
                actor_sum += loss;
                actor_steps += 1;
            }
        }
        let mut stats = Vec::new();
        if actor_steps > 0 {
            stats.push(("train/actor_loss", actor_sum / actor_steps as f32));
        }
        stats.push((
            "train/critic_loss",
            critic_sum / gradient_steps.max(1) as f32,
        ));
        stats.push(("train/learning_rate", self.config.learning_rate as f32));
        Ok(stats)
    }

    /// Target policy smoothing: `clip(μ'(s') + clip(σ ε, −c, c), −1, 1)` for standard normal
    /// `eps`.
    fn smoothed_target_actions(&self, next_obs: &Tensor, eps: &Tensor) -> Result<Tensor> {
        let c = self.config.target_noise_clip as f64;
        let noise = (eps * self.config.target_policy_noise as f64)?.clamp(-c, c)?;
        let actions = self.policy.actor_target.forward(next_obs)?;
        Ok((actions + noise)?.clamp(-1.0, 1.0)?)
    }

    /// One critic step, and every `policy_delay`-th step an actor step and the target updates.
    /// Returns the critic loss and the actor loss (when the actor learnt).
    fn gradient_step(&mut self) -> Result<(f32, Option<f32>)> {
        let b = self.config.batch_size;
        let Batch {
            obs,
            actions,
            rewards,
            next_obs,
            not_done,
        } = self.core.sample_batch()?;

        let eps = self.core.noise(b)?;
        let next_actions = self.smoothed_target_actions(&next_obs, &eps)?;
        let policy = &self.policy;
        let next_q = policy.critics.target.min_q(&next_obs, &next_actions)?;
        let target = (rewards + ((not_done * next_q)? * self.config.gamma as f64)?)?.detach();

        let (q1, q2) = policy.critics.online.q(&obs, &actions)?;
        let critic_loss =
            ((q1 - &target)?.sqr()?.mean_all()? + (q2 - &target)?.sqr()?.mean_all()?)?;
        self.critic_opt.backward_step(&critic_loss, 0.0)?;
        self.core.n_updates += 1;

        let mut actor_loss = None;
        if self
            .core
            .n_updates
            .is_multiple_of(self.config.policy_delay as u64)
        {
            // Deterministic policy gradient through the first critic, its weights constant.
            let loss = policy
                .critics
                .online
                .q1_detached(&obs, &policy.actor.forward(&obs)?)?
                .mean_all()?
                .neg()?;
            self.actor_opt.backward_step(&loss, 0.0)?;
            policy.soft_update(self.config.tau)?;
            actor_loss = Some(loss.to_scalar::<f32>()?);
        }
        Ok((critic_loss.to_scalar()?, actor_loss))
    }
}

impl OffPolicy for Td3 {
    const NAME: &'static str = "td3";
    /// Actor and critics.
    type Optimizers = (Adam, Adam);

    fn core(&self) -> &OffPolicyCore {
        &self.core
    }

    fn actor_and_core(&mut self) -> (&dyn ActorNet, &mut OffPolicyCore) {
        (&self.policy.actor, &mut self.core)
    }

    fn train(&mut self, gradient_steps: u64) -> Result<Vec<(&'static str, f32)>> {
        Td3::train(self, gradient_steps)
    }

    fn networks(&self) -> TensorMap {
        let mut out = TensorMap::new();
        for (_, varmap) in self.policy.groups() {
            out.extend(varmap_tensors(varmap, ""));
        }
        out
    }

    fn load_networks(&mut self, weights: &TensorMap) -> Result<()> {
        let scratch = DeterministicPolicy::zeroed(
            self.core.obs_dim,
            self.core.act_dim,
            &self.config.net(),
            self.config.action_noise,
        )?;
        load_grouped(&self.policy.groups(), &scratch.groups(), weights)
    }

    fn optimizers(&self) -> Vec<(&'static str, &Adam)> {
        vec![
            ("actor_opt.", &self.actor_opt),
            ("critic_opt.", &self.critic_opt),
        ]
    }

    fn read_optimizers(&self, state: &TensorMap) -> Result<Self::Optimizers> {
        let lr = self.config.learning_rate;
        let actor_opt = load_adam(state, "actor_opt.", &self.policy.actor.varmap, lr)?;
        let critic_opt = load_adam(state, "critic_opt.", &self.policy.critics.online.varmap, lr)?;
        Ok((actor_opt, critic_opt))
    }

    fn set_optimizers(&mut self, (actor, critic): Self::Optimizers) {
        (self.actor_opt, self.critic_opt) = (actor, critic);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithm::Algorithm;
    use crate::off_policy::test_support::{
        assert_training_state_resumes, assert_validate_names_keys, fill_replay, group, pendulums,
        unit_box_error, weights_of,
    };
    use candle_core::{DType, Device};

    fn small_config() -> Td3Config {
        Td3Config {
            buffer_size: 1_000,
            learning_starts: 40,
            batch_size: 16,
            net_arch: vec![16, 16],
            // Fractional steps per iteration with two envs, so the accumulator matters.
            utd_ratio: 0.75,
            ..Td3Config::default()
        }
    }

    /// A learner with 60 transitions in its buffer and no gradient step taken.
    fn filled(config: Td3Config, seed: u64) -> Td3 {
        let mut td3 = Td3::new(config, 3, 1, 2, seed).unwrap();
        fill_replay(&mut td3.core.buffer, 60);
        td3
    }

    #[test]
    fn a_seed_fixes_the_initial_networks_and_targets_start_as_copies() {
        let a = weights_of(&Td3::new(small_config(), 3, 1, 2, 5).unwrap());
        let b = weights_of(&Td3::new(small_config(), 3, 1, 2, 5).unwrap());
        let c = weights_of(&Td3::new(small_config(), 3, 1, 2, 6).unwrap());
        assert_eq!(a, b);
        assert_ne!(a["actor.l0.weight"], c["actor.l0.weight"]);
        assert_eq!(a["actor.l2.weight"], a["actor_target.l2.weight"]);
        assert_eq!(a["critic.qf2.l1.weight"], a["critic_target.qf2.l1.weight"]);
        assert_eq!(a.len(), 6 + 6 + 12 + 12);
    }

    #[test]
    fn the_actor_and_the_targets_learn_every_policy_delay_critic_steps() {
        let mut td3 = filled(small_config(), 1);
        let w0 = weights_of(&td3);
        // Step 1: only the critics move; no actor loss is logged.
        let stats = td3.train(1).unwrap();
        let names: Vec<&str> = stats.iter().map(|s| s.0).collect();
        assert_eq!(names, ["train/critic_loss", "train/learning_rate"]);
        let w1 = weights_of(&td3);
        assert_ne!(group(&w1, "critic."), group(&w0, "critic."));
        for prefix in ["actor.", "actor_target.", "critic_target."] {
            assert_eq!(group(&w1, prefix), group(&w0, prefix), "{prefix} moved");
        }
        // Step 2: the actor learns and both targets move towards their networks.
        let stats = td3.train(1).unwrap();
        assert_eq!(stats[0].0, "train/actor_loss");
        let w2 = weights_of(&td3);
        for prefix in ["actor.", "actor_target.", "critic.", "critic_target."] {
            assert_ne!(
                group(&w2, prefix),
                group(&w1, prefix),
                "{prefix} did not move"
            );
        }
        let tau = td3.config.tau;
        for ((name, t2), (_, t1)) in group(&w2, "actor_target.")
            .iter()
            .zip(group(&w1, "actor_target."))
        {
            let online = &w2[&name.replacen("actor_target.", "actor.", 1)];
            for k in 0..t2.len() {
                let want = (1.0 - tau) * t1[k] + tau * online[k];
                assert!(
                    (t2[k] - want).abs() <= 1e-6 * (1.0 + want.abs()),
                    "{name}[{k}]"
                );
            }
        }
        assert_eq!(td3.n_updates(), 2);

        // With policy_delay 3: two critic-only steps, then the actor.
        let mut td3 = filled(
            Td3Config {
                policy_delay: 3,
                ..small_config()
            },
            1,
        );
        let w0 = weights_of(&td3);
        td3.train(2).unwrap();
        assert_eq!(group(&weights_of(&td3), "actor."), group(&w0, "actor."));
        td3.train(1).unwrap();
        assert_ne!(group(&weights_of(&td3), "actor."), group(&w0, "actor."));
    }

    #[test]
    fn target_policy_smoothing_clips_the_noise_then_the_action() {
        let config = Td3Config {
            target_policy_noise: 0.2,
            target_noise_clip: 0.5,
            ..small_config()
        };
        let td3 = Td3::new(config, 3, 1, 1, 0).unwrap();
        let dev = &Device::Cpu;
        let next_obs = Tensor::new(
            &[[0.1f32, 0.2, 0.3], [-0.5, 0.4, 1.0], [0.0, 0.0, 0.0]],
            dev,
        )
        .unwrap();
        let mu: Vec<f32> = td3
            .policy
            .actor_target
            .forward(&next_obs)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let smoothed = |eps: [f32; 3]| -> Vec<f32> {
            let eps = Tensor::new(&eps, dev).unwrap().reshape((3, 1)).unwrap();
            td3.smoothed_target_actions(&next_obs, &eps)
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap()
        };
        // σ ε within the clip: added as is.
        let small = smoothed([1.0, -1.0, 0.0]);
        for (k, want) in [mu[0] + 0.2, mu[1] - 0.2, mu[2]].iter().enumerate() {
            assert!((small[k] - want).abs() < 1e-6, "{small:?} vs {mu:?}");
        }
        // 0.2 × 10 = 2 is clipped to 0.5, then the action to [-1, 1] (μ' is near 0 at first).
        let large = smoothed([10.0, -10.0, 1e6]);
        for (k, want) in [mu[0] + 0.5, mu[1] - 0.5, mu[2] + 0.5].iter().enumerate() {
            assert!(
                (large[k] - want.clamp(-1.0, 1.0)).abs() < 1e-6,
                "{large:?} vs {mu:?}"
            );
        }
        let mut wide = Td3::new(
            Td3Config {
                target_noise_clip: 5.0,
                ..small_config()
            },
            3,
            1,
            1,
            0,
        )
        .unwrap();
        wide.config.target_policy_noise = 1.0;
        let eps = Tensor::new(&[[3.0f32], [-3.0], [0.0]], dev).unwrap();
        let clipped: Vec<f32> = wide
            .smoothed_target_actions(&next_obs, &eps)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        assert_eq!(&clipped[..2], &[1.0, -1.0]);
    }

    #[test]
    fn exploration_adds_clipped_gaussian_noise_and_deterministic_actions_do_not() {
        let mut td3 = Td3::new(small_config(), 3, 1, 1, 0).unwrap();
        let obs = [0.3f32, -0.2, 0.5];
        let mean = td3.predict(&obs, true).unwrap();
        assert_eq!(mean, td3.predict(&obs, true).unwrap());
        let noisy: Vec<f32> = (0..2000)
            .map(|_| td3.predict(&obs, false).unwrap()[0] - mean[0])
            .collect();
        let m = noisy.iter().sum::<f32>() / noisy.len() as f32;
        let sd = (noisy.iter().map(|x| (x - m).powi(2)).sum::<f32>() / noisy.len() as f32).sqrt();
        assert!(
            m.abs() < 0.01 && (sd - 0.1).abs() < 0.01,
            "mean {m}, sd {sd}"
        );
    }

    #[test]
    fn training_state_round_trip_continues_bit_exactly() {
        let mut a = Td3::new(small_config(), 3, 1, 2, 1).unwrap();
        let mut venv = pendulums(2, 1);
        // 25 learning iterations of 1.5 steps: 37 critic steps and half a step owed.
        for _ in 0..44 {
            a.learn_iteration(&mut venv, 1.0, &mut |_| {}).unwrap();
        }
        assert!(a.n_updates() > 20 && a.core.grad_accumulator != 0.0);
        // An odd number of critic steps, so the delay's phase must carry over too.
        assert_eq!(a.n_updates() % 2, 1, "{}", a.n_updates());
        let weights = a.weights().unwrap();
        assert_training_state_resumes(
            &mut a,
            || Td3::new(small_config(), 3, 1, 2, 99).unwrap(),
            Td3::n_updates,
            &[
                "actor_opt.adam.m.actor.l0.bias",
                "td3.rng.seed",
                "td3.replay.actions",
                "td3.n_updates",
            ],
        );
        let mut extra = weights.clone();
        extra.insert(
            "critic.qf3.l0.weight".into(),
            Tensor::zeros(1, DType::F32, &Device::Cpu).unwrap(),
        );
        let err = a.load_weights(&extra).unwrap_err().to_string();
        assert!(err.contains("critic.qf3.l0.weight"), "{err}");
    }

    #[test]
    fn validate_names_each_bad_setting() {
        let d = Td3Config::default;
        let cases: Vec<(&str, Td3Config)> = vec![
            (
                "learning_rate",
                Td3Config {
                    learning_rate: -1.0,
                    ..d()
                },
            ),
            (
                "buffer_size",
                Td3Config {
                    buffer_size: 0,
                    ..d()
                },
            ),
            (
                "batch_size",
                Td3Config {
                    batch_size: 0,
                    ..d()
                },
            ),
            ("tau", Td3Config { tau: 0.0, ..d() }),
            ("gamma", Td3Config { gamma: 1.5, ..d() }),
            (
                "utd_ratio",
                Td3Config {
                    utd_ratio: f32::NAN,
                    ..d()
                },
            ),
            (
                "policy_delay",
                Td3Config {
                    policy_delay: 0,
                    ..d()
                },
            ),
            (
                "target_policy_noise",
                Td3Config {
                    target_policy_noise: -0.2,
                    ..d()
                },
            ),
            (
                "target_noise_clip",
                Td3Config {
                    target_noise_clip: f32::INFINITY,
                    ..d()
                },
            ),
            (
                "action_noise",
                Td3Config {
                    action_noise: -0.1,
                    ..d()
                },
            ),
            (
                "net_arch",
                Td3Config {
                    net_arch: vec![],
                    ..d()
                },
            ),
        ];
        assert_validate_names_keys("td3", validate, &d(), cases);
    }

    #[test]
    fn environments_outside_the_unit_box_are_refused() {
        let mut td3 = Td3::new(small_config(), 3, 1, 1, 0).unwrap();
        let err = unit_box_error(&mut td3);
        assert!(
            err.contains("TD3") && err.contains("RescaleAction"),
            "{err}"
        );
    }
}
