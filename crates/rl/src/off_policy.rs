//! What the off-policy algorithms (SAC, TD3) share, so each of them is only its gradient step:
//! the replay-driven learn loop (collect one vector step, store it, owe `utd_ratio` gradient
//! steps per transition), minibatches as tensors, the random stream, and their checkpoint state.
//! The networks they share (twin critics, Polyak-averaged targets) are in
//! [`crate::policies::critics`].

use crate::algorithm::{Algorithm, TensorMap, rng_from_state, rng_state};
use crate::buffers::{ReplayBuffer, ReplaySample};
use crate::error::{ConfigSection, Result, RlError};
use crate::nn::Adam;
use crate::policies::ActorNet;
use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use fairgrasp_env::{VecStep, VectorEnv};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[cfg(test)]
pub(crate) mod test_support;

/// The settings of the learn loop (each algorithm's config has them under SB3's names).
#[derive(Clone, Copy, Debug)]
pub struct LoopSettings {
    /// Replay buffer capacity, in transitions (SB3's `buffer_size`); at least 1.
    pub buffer_size: usize,
    /// Environment steps (all environments together) of uniformly random actions before
    /// learning starts (SB3's `learning_starts`).
    pub learning_starts: u64,
    /// Transitions per minibatch (SB3's `batch_size`); at least 1.
    pub batch_size: usize,
    /// Update-to-data ratio: gradient steps per transition collected; positive.
    pub utd_ratio: f32,
    /// Checkpoints hold the replay buffer, so a resumed run continues with it.
    pub save_replay_buffer: bool,
}

/// The [`LoopSettings`] of an algorithm's config, whose fields bear the same names.
macro_rules! loop_settings {
    ($config:expr) => {
        $crate::off_policy::LoopSettings {
            buffer_size: $config.buffer_size,
            learning_starts: $config.learning_starts,
            batch_size: $config.batch_size,
            utd_ratio: $config.utd_ratio,
            save_replay_buffer: $config.save_replay_buffer,
        }
    };
}
pub(crate) use loop_settings;

/// An off-policy learner: its networks, optimisers and gradient step on the shared
/// [`OffPolicyCore`]. Every `OffPolicy` is an [`Algorithm`] through the one impl below, so SAC
/// and TD3 are only what differs between them.
pub trait OffPolicy {
    /// Short lowercase name, stored in saved models.
    const NAME: &'static str;
    /// The optimisers' states read from a checkpoint, not yet in place.
    type Optimizers;

    /// The shared experience side.
    fn core(&self) -> &OffPolicyCore;

    /// The acting network and the core together (acting draws from the core's stream).
    fn actor_and_core(&mut self) -> (&dyn ActorNet, &mut OffPolicyCore);

    /// `gradient_steps` gradient steps on replayed minibatches; the `train/*` means to log.
    fn train(&mut self, gradient_steps: u64) -> Result<Vec<(&'static str, f32)>>;

    /// The weights of every network (the model's `model.safetensors`).
    fn networks(&self) -> TensorMap;

    /// Loads weights saved by [`Self::networks`]; a bad tensor is an error naming it and
    /// changes nothing.
    fn load_networks(&mut self, weights: &TensorMap) -> Result<()>;

    /// The optimisers under their checkpoint prefixes (`actor_opt.`, …).
    fn optimizers(&self) -> Vec<(&'static str, &Adam)>;

    /// The optimisers saved in `state`, read without changing anything.
    fn read_optimizers(&self, state: &TensorMap) -> Result<Self::Optimizers>;

    /// Puts optimisers read by [`Self::read_optimizers`] in place.
    fn set_optimizers(&mut self, optimizers: Self::Optimizers);
}

impl<T: OffPolicy> Algorithm for T {
    fn name(&self) -> &'static str {
        T::NAME
    }

    fn log_interval(&self) -> u64 {
        // One iteration per vector step: logging every iteration would write a row per step.
        1000
    }

    fn num_timesteps(&self) -> u64 {
        self.core().num_timesteps
    }

    fn set_num_timesteps(&mut self, steps: u64) {
        self.actor_and_core().1.num_timesteps = steps;
    }

    fn learn_iteration<V: VectorEnv>(
        &mut self,
        venv: &mut V,
        _progress_remaining: f64,
        on_step: &mut dyn FnMut(&VecStep<'_>),
    ) -> Result<Vec<(&'static str, f32)>> {
        let (actor, core) = self.actor_and_core();
        let steps = core.collect(venv, on_step, |obs, rng| actor.act(obs, false, rng))?;
        if steps == 0 {
            return Ok(Vec::new());
        }
        self.train(steps)
    }

    fn predict(&mut self, obs: &[f32], deterministic: bool) -> Result<Vec<f32>> {
        let (actor, core) = self.actor_and_core();
        actor.act(obs, deterministic, &mut core.rng)
    }

    fn weights(&self) -> Result<TensorMap> {
        Ok(self.networks())
    }

    fn load_weights(&mut self, weights: &TensorMap) -> Result<()> {
        self.load_networks(weights)
    }

    fn training_state(&self) -> Result<TensorMap> {
        self.core().training_state(&self.optimizers())
    }

    fn load_training_state(&mut self, state: &TensorMap) -> Result<()> {
        // Everything is read into new values first, so a bad state changes nothing.
        let optimizers = self.read_optimizers(state)?;
        let core = self.actor_and_core().1;
        core.read_state(state)?.apply(core, state)?;
        self.set_optimizers(optimizers);
        Ok(())
    }

    fn rng_mut(&mut self) -> &mut ChaCha8Rng {
        &mut self.actor_and_core().1.rng
    }
}

/// The checks SAC and TD3 share, in their configs' order.
pub(crate) fn check_shared_settings(
    section: &ConfigSection,
    learning_rate: f64,
    settings: &LoopSettings,
    tau: f32,
    gamma: f32,
) -> Result<()> {
    section.positive("learning_rate", learning_rate)?;
    section.at_least_one("buffer_size", settings.buffer_size)?;
    section.at_least_one("batch_size", settings.batch_size)?;
    if !(tau > 0.0 && tau <= 1.0) {
        return section.bad("tau", format!("must be in (0, 1], got {tau}"));
    }
    section.in_unit_interval("gamma", gamma)?;
    section.positive("utd_ratio", settings.utd_ratio)
}

/// A minibatch as tensors: `obs`, `next_obs` are `batch × obs_dim`, `actions` `batch × act_dim`,
/// `rewards` and `not_done` (1 − terminated) `batch`.
pub struct Batch {
    /// Observations.
    pub obs: Tensor,
    /// Actions taken.
    pub actions: Tensor,
    /// Rewards.
    pub rewards: Tensor,
    /// Observations after the actions.
    pub next_obs: Tensor,
    /// 0 where the next observation is terminal, else 1.
    pub not_done: Tensor,
}

/// The experience side of an off-policy learner: replay buffer, random stream and counters.
pub struct OffPolicyCore {
    /// `"sac"` or `"td3"`: messages and the checkpoint keys' prefix (`sac.rng.seed`, …).
    name: &'static str,
    /// The learn loop's settings.
    pub settings: LoopSettings,
    /// The replay buffer.
    pub buffer: ReplayBuffer,
    /// Reused minibatch storage.
    sample: ReplaySample,
    /// Random stream for exploration, minibatch sampling and noise.
    pub rng: ChaCha8Rng,
    /// Environment steps taken so far (all environments together).
    pub num_timesteps: u64,
    /// Gradient steps owed but not yet taken (fractional when `utd_ratio × n_envs` is not an
    /// integer).
    pub grad_accumulator: f64,
    /// Gradient steps taken so far.
    pub n_updates: u64,
    /// Observation width.
    pub obs_dim: usize,
    /// Action width.
    pub act_dim: usize,
}

impl OffPolicyCore {
    /// A core with an empty replay buffer and a stream seeded with `seed`; `name` (`"sac"`,
    /// `"td3"`) prefixes its checkpoint keys. Errors on zero-width observations or actions.
    pub fn new(
        name: &'static str,
        settings: LoopSettings,
        obs_dim: usize,
        act_dim: usize,
        seed: u64,
    ) -> Result<Self> {
        if obs_dim == 0 || act_dim == 0 {
            return Err(RlError::Other(format!(
                "{} needs observations and actions, got {obs_dim} and {act_dim} values",
                name.to_uppercase()
            )));
        }
        Ok(Self {
            name,
            settings,
            buffer: ReplayBuffer::new(settings.buffer_size, obs_dim, act_dim),
            sample: ReplaySample::default(),
            rng: ChaCha8Rng::seed_from_u64(seed),
            num_timesteps: 0,
            grad_accumulator: 0.0,
            n_updates: 0,
            obs_dim,
            act_dim,
        })
    }

    /// Errors when `venv` is not the environment this learner was built for, or acts outside
    /// the `[-1, 1]` box the tanh policies cover.
    pub fn check_env<V: VectorEnv>(&self, venv: &V) -> Result<()> {
        let name = self.name.to_uppercase();
        if venv.obs_dim() != self.obs_dim || venv.act_dim() != self.act_dim {
            return Err(RlError::Other(format!(
                "{name} was built for {} observation and {} action values, the environments \
                 have {} and {}",
                self.obs_dim,
                self.act_dim,
                venv.obs_dim(),
                venv.act_dim()
            )));
        }
        let space = venv.action_space();
        if space.low.iter().any(|&l| l != -1.0) || space.high.iter().any(|&h| h != 1.0) {
            return Err(RlError::Other(format!(
                "{name}'s actions lie in [-1, 1], the environments' action space is {:?} to \
                 {:?}; wrap them in RescaleAction",
                space.low, space.high
            )));
        }
        Ok(())
    }

    /// One step of every environment (uniformly random actions for the first
    /// `learning_starts` steps, else `act(observations, rng)`), its transitions into the replay
    /// buffer. Returns the gradient steps owed now (0 before `learning_starts`).
    pub fn collect<V: VectorEnv>(
        &mut self,
        venv: &mut V,
        on_step: &mut dyn FnMut(&VecStep<'_>),
        act: impl FnOnce(&[f32], &mut ChaCha8Rng) -> Result<Vec<f32>>,
    ) -> Result<u64> {
        self.check_env(venv)?;
        let (n, od, ad) = (venv.num_envs(), self.obs_dim, self.act_dim);
        let obs = venv.observations().to_vec();
        let actions: Vec<f32> = if self.num_timesteps < self.settings.learning_starts {
            (0..n * ad)
                .map(|_| self.rng.random_range(-1.0..=1.0))
                .collect()
        } else {
            act(&obs, &mut self.rng)?
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
        if self.num_timesteps < self.settings.learning_starts {
            return Ok(0);
        }
        self.grad_accumulator += self.settings.utd_ratio as f64 * n as f64;
        let steps = self.grad_accumulator.floor();
        self.grad_accumulator -= steps;
        Ok(steps as u64)
    }

    /// A minibatch of `batch_size` transitions drawn uniformly (with replacement).
    pub fn sample_batch(&mut self) -> Result<Batch> {
        if self.buffer.is_empty() {
            return Err(RlError::Other(format!(
                "{} cannot train on an empty replay buffer",
                self.name.to_uppercase()
            )));
        }
        let (b, od, ad) = (self.settings.batch_size, self.obs_dim, self.act_dim);
        let dev = &Device::Cpu;
        self.buffer.sample_into(b, &mut self.rng, &mut self.sample);
        let s = &self.sample;
        Ok(Batch {
            obs: Tensor::from_slice(&s.observations, (b, od), dev)?,
            actions: Tensor::from_slice(&s.actions, (b, ad), dev)?,
            rewards: Tensor::from_slice(&s.rewards, b, dev)?,
            next_obs: Tensor::from_slice(&s.next_observations, (b, od), dev)?,
            not_done: Tensor::from_slice(&s.dones, b, dev)?.affine(-1.0, 1.0)?,
        })
    }

    /// `rows × act_dim` standard normal noise from the learner's stream (not candle's unseeded
    /// one), so a seeded run is reproducible.
    pub fn noise(&mut self, rows: usize) -> Result<Tensor> {
        Ok(crate::distributions::standard_normal_tensor(
            &mut self.rng,
            rows,
            self.act_dim,
        )?)
    }

    /// Random stream, counters and (if `save_replay_buffer`) the replay buffer, under
    /// `{name}.`.
    pub fn state(&self) -> Result<TensorMap> {
        let dev = &Device::Cpu;
        let p = self.name;
        let mut state = rng_state(&self.rng, &format!("{p}."))?;
        state.insert(
            format!("{p}.grad_accumulator"),
            Tensor::new(&[self.grad_accumulator], dev)?,
        );
        state.insert(
            format!("{p}.n_updates"),
            Tensor::new(&[self.n_updates as f64], dev)?,
        );
        if self.settings.save_replay_buffer {
            state.extend(self.buffer.state(&format!("{p}.replay."))?);
        }
        Ok(state)
    }

    /// The optimisers' states, each under its prefix (`actor_opt.adam.m.…`), with
    /// [`Self::state`]: an algorithm's whole training state.
    pub fn training_state(&self, optimizers: &[(&str, &Adam)]) -> Result<TensorMap> {
        let mut state = TensorMap::new();
        for (prefix, opt) in optimizers {
            state.extend(
                opt.state()?
                    .into_iter()
                    .map(|(k, v)| (format!("{prefix}{k}"), v)),
            );
        }
        state.extend(self.state()?);
        Ok(state)
    }

    /// Reads the counters and stream of a state saved by [`Self::state`] without changing
    /// anything; [`Restored::apply`] puts them and the buffer in place (so an algorithm can
    /// check its own parts first).
    pub fn read_state(&self, state: &TensorMap) -> Result<Restored> {
        let p = self.name;
        let rng = rng_from_state(state, &format!("{p}."))?;
        let grad_accumulator = state_scalar(state, &format!("{p}.grad_accumulator"))?;
        let n_updates = state_scalar(state, &format!("{p}.n_updates"))? as u64;
        Ok(Restored {
            rng,
            grad_accumulator,
            n_updates,
        })
    }
}

/// A state read by [`OffPolicyCore::read_state`], not yet applied.
pub struct Restored {
    rng: ChaCha8Rng,
    grad_accumulator: f64,
    n_updates: u64,
}

impl Restored {
    /// Loads the replay buffer from `state` (the last check: a bad one changes nothing), then
    /// the rest.
    pub fn apply(self, core: &mut OffPolicyCore, state: &TensorMap) -> Result<()> {
        // A run that keeps its buffer in checkpoints needs it back; otherwise a state without
        // one resumes with the buffer as it is (empty in a fresh learner, as in SB3).
        let prefix = format!("{}.replay.", core.name);
        if core.settings.save_replay_buffer || state.contains_key(&format!("{prefix}rewards")) {
            core.buffer
                .load_state(state, &prefix)
                .map_err(RlError::Model)?;
        }
        core.rng = self.rng;
        core.grad_accumulator = self.grad_accumulator;
        core.n_updates = self.n_updates;
        Ok(())
    }
}

/// A new optimiser of `varmap` with the moments saved under `prefix` in `state` (by
/// [`OffPolicyCore::training_state`]); an error names what is missing and the prefix.
pub fn load_adam(state: &TensorMap, prefix: &str, varmap: &VarMap, lr: f64) -> Result<Adam> {
    let mut opt = Adam::new(varmap, lr)?;
    opt.load_state(&unprefixed(state, prefix))
        .map_err(|e| RlError::Model(format!("{e} (under `{prefix}`)")))?;
    Ok(opt)
}

/// The entries of `state` under `prefix`, without it.
pub fn unprefixed(state: &TensorMap, prefix: &str) -> TensorMap {
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
