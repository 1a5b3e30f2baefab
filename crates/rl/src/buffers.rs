//! Experience storage: the on-policy rollout buffer (with GAE) and the off-policy replay buffer.

use candle_core::Tensor;
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// Transitions of one PPO rollout: `n_steps` steps of `n_envs` environments, stored step-major
/// (`index = step * n_envs + env`), like SB3's `RolloutBuffer`.
#[derive(Clone, Debug)]
pub struct RolloutBuffer {
    /// Steps per environment (SB3's `n_steps`).
    pub n_steps: usize,
    /// Environments stepped together.
    pub n_envs: usize,
    /// Observation width.
    pub obs_dim: usize,
    /// Action width.
    pub act_dim: usize,
    /// `n_steps·n_envs × obs_dim`, row-major.
    pub observations: Vec<f32>,
    /// Actions as sampled by the policy (before clipping to the action space).
    pub actions: Vec<f32>,
    /// One per transition; truncated episodes' last rewards include the bootstrap `γ·V`.
    pub rewards: Vec<f32>,
    /// Whether the observation at this step starts a new episode (SB3's `episode_starts`).
    pub episode_starts: Vec<bool>,
    /// The value network's estimate of each observation.
    pub values: Vec<f32>,
    /// Log-probability (nats) of each action under the policy that took it.
    pub log_probs: Vec<f32>,
    /// GAE advantages, set by [`Self::compute_returns_and_advantages`].
    pub advantages: Vec<f32>,
    /// Advantages plus values: the value network's targets.
    pub returns: Vec<f32>,
    /// Values of the privileged state per transition (0: no privileged critic).
    pub privileged_dim: usize,
    /// Each observation's privileged state, as the value network read it.
    pub privileged: Vec<f32>,
    /// Bytes of camera images per transition (0: none).
    pub image_len: usize,
    /// Each observation's camera images, as the cameras gave them (`u8`, no float copy).
    pub images: Vec<u8>,
    len: usize,
}

impl RolloutBuffer {
    /// An empty buffer for `n_steps` steps of `n_envs` environments, without privileged state.
    pub fn new(n_steps: usize, n_envs: usize, obs_dim: usize, act_dim: usize) -> Self {
        let n = n_steps * n_envs;
        Self {
            n_steps,
            n_envs,
            obs_dim,
            act_dim,
            observations: vec![0.0; n * obs_dim],
            actions: vec![0.0; n * act_dim],
            rewards: vec![0.0; n],
            episode_starts: vec![false; n],
            values: vec![0.0; n],
            log_probs: vec![0.0; n],
            advantages: vec![0.0; n],
            returns: vec![0.0; n],
            privileged_dim: 0,
            privileged: Vec::new(),
            image_len: 0,
            images: Vec::new(),
            len: 0,
        }
    }

    /// The buffer, also storing `dim` privileged values per transition.
    pub fn with_privileged(mut self, dim: usize) -> Self {
        self.privileged_dim = dim;
        self.privileged = vec![0.0; self.n_steps * self.n_envs * dim];
        self
    }

    /// The buffer, also storing `len` bytes of camera images per transition.
    pub fn with_images(mut self, len: usize) -> Self {
        self.image_len = len;
        self.images = vec![0; self.n_steps * self.n_envs * len];
        self
    }

    /// Stores the images of the step [`Self::push`] is about to store (`n_envs × image_len`
    /// bytes).
    pub fn push_images(&mut self, images: &[u8]) {
        assert!(!self.is_full(), "rollout buffer is full");
        let (n, t, l) = (self.n_envs, self.len, self.image_len);
        self.images[t * n * l..(t + 1) * n * l].copy_from_slice(images);
    }

    /// Transitions stored so far (steps × envs).
    pub fn len(&self) -> usize {
        self.len * self.n_envs
    }

    /// Whether no step is stored.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Whether all `n_steps` steps are stored.
    pub fn is_full(&self) -> bool {
        self.len == self.n_steps
    }

    /// Forgets the stored steps (the storage is kept).
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Stores one step of every environment (`privileged`: `n_envs × privileged_dim` values).
    #[allow(clippy::too_many_arguments)]
    pub fn push(
        &mut self,
        observations: &[f32],
        actions: &[f32],
        rewards: &[f32],
        episode_starts: &[bool],
        values: &[f32],
        log_probs: &[f32],
        privileged: &[f32],
    ) {
        assert!(!self.is_full(), "rollout buffer is full");
        let (n, t) = (self.n_envs, self.len);
        let pd = self.privileged_dim;
        self.privileged[t * n * pd..(t + 1) * n * pd].copy_from_slice(privileged);
        self.observations[t * n * self.obs_dim..(t + 1) * n * self.obs_dim]
            .copy_from_slice(observations);
        self.actions[t * n * self.act_dim..(t + 1) * n * self.act_dim].copy_from_slice(actions);
        self.rewards[t * n..(t + 1) * n].copy_from_slice(rewards);
        self.episode_starts[t * n..(t + 1) * n].copy_from_slice(episode_starts);
        self.values[t * n..(t + 1) * n].copy_from_slice(values);
        self.log_probs[t * n..(t + 1) * n].copy_from_slice(log_probs);
        self.len += 1;
    }

    /// Adds `γ·V(terminal observation)` to a stored reward: how truncated episodes are
    /// bootstrapped (SB3 does the same for time-limit truncation).
    pub fn add_to_last_reward(&mut self, env: usize, value: f32) {
        let t = self.len - 1;
        self.rewards[t * self.n_envs + env] += value;
    }

    /// Generalised advantage estimation (Schulman et al. 2016):
    /// `δ_t = r_t + γ V(s_{t+1}) (1 − start_{t+1}) − V(s_t)`,
    /// `A_t = δ_t + γλ (1 − start_{t+1}) A_{t+1}`, `R_t = A_t + V(s_t)`.
    /// `last_values` are the values of the observations after the last step and `dones` whether
    /// those observations start new episodes.
    pub fn compute_returns_and_advantages(
        &mut self,
        last_values: &[f32],
        dones: &[bool],
        gamma: f32,
        gae_lambda: f32,
    ) {
        let n = self.n_envs;
        for env in 0..n {
            let mut last_gae = 0.0;
            for t in (0..self.len).rev() {
                let (next_non_terminal, next_value) = if t + 1 == self.len {
                    (if dones[env] { 0.0 } else { 1.0 }, last_values[env])
                } else {
                    let i = (t + 1) * n + env;
                    (
                        if self.episode_starts[i] { 0.0 } else { 1.0 },
                        self.values[i],
                    )
                };
                let i = t * n + env;
                let delta =
                    self.rewards[i] + gamma * next_value * next_non_terminal - self.values[i];
                last_gae = delta + gamma * gae_lambda * next_non_terminal * last_gae;
                self.advantages[i] = last_gae;
                self.returns[i] = last_gae + self.values[i];
            }
        }
    }
}

/// A ring buffer of transitions for off-policy learning (SB3's `ReplayBuffer`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ReplayBuffer {
    /// Transitions held before the oldest are overwritten (SB3's `buffer_size`).
    pub capacity: usize,
    /// Observation width.
    pub obs_dim: usize,
    /// Action width.
    pub act_dim: usize,
    observations: Vec<f32>,
    next_observations: Vec<f32>,
    actions: Vec<f32>,
    rewards: Vec<f32>,
    /// 1.0 when the next observation is terminal (no bootstrap), else 0.0. Truncations are not
    /// terminal: their next observation is the real final one and is bootstrapped.
    dones: Vec<f32>,
    position: usize,
    full: bool,
}

/// A sampled minibatch, row-major.
#[derive(Clone, Debug, Default)]
pub struct ReplaySample {
    /// `batch × obs_dim`.
    pub observations: Vec<f32>,
    /// `batch × act_dim`, as taken.
    pub actions: Vec<f32>,
    /// One per transition.
    pub rewards: Vec<f32>,
    /// `batch × obs_dim`: the observation after the action (the real final one where an
    /// episode ended).
    pub next_observations: Vec<f32>,
    /// 1.0 where the next observation is terminal (no bootstrap), else 0.0.
    pub dones: Vec<f32>,
}

impl ReplayBuffer {
    /// An empty buffer of `capacity` transitions.
    pub fn new(capacity: usize, obs_dim: usize, act_dim: usize) -> Self {
        Self {
            capacity,
            obs_dim,
            act_dim,
            observations: vec![0.0; capacity * obs_dim],
            next_observations: vec![0.0; capacity * obs_dim],
            actions: vec![0.0; capacity * act_dim],
            rewards: vec![0.0; capacity],
            dones: vec![0.0; capacity],
            position: 0,
            full: false,
        }
    }

    /// Transitions stored (at most `capacity`).
    pub fn len(&self) -> usize {
        if self.full {
            self.capacity
        } else {
            self.position
        }
    }

    /// Whether no transition is stored.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Stores one transition.
    pub fn push(
        &mut self,
        obs: &[f32],
        action: &[f32],
        reward: f32,
        next_obs: &[f32],
        terminal: bool,
    ) {
        let i = self.position;
        self.observations[i * self.obs_dim..(i + 1) * self.obs_dim].copy_from_slice(obs);
        self.next_observations[i * self.obs_dim..(i + 1) * self.obs_dim].copy_from_slice(next_obs);
        self.actions[i * self.act_dim..(i + 1) * self.act_dim].copy_from_slice(action);
        self.rewards[i] = reward;
        self.dones[i] = if terminal { 1.0 } else { 0.0 };
        self.position = (self.position + 1) % self.capacity;
        self.full |= self.position == 0;
    }

    /// The stored transitions (only the filled part) with the write position and the `full`
    /// flag, as named tensors for a checkpoint: `{prefix}observations`, `…next_observations`
    /// (`len × obs_dim`), `…actions` (`len × act_dim`), `…rewards`, `…dones` (`len`), `…position`
    /// and `…full` (one value each).
    pub fn state(&self, prefix: &str) -> candle_core::Result<HashMap<String, Tensor>> {
        let dev = &candle_core::Device::Cpu;
        let n = self.len();
        let (od, ad) = (self.obs_dim, self.act_dim);
        let mut out = HashMap::new();
        let mut put = |name: &str, t: Tensor| out.insert(format!("{prefix}{name}"), t);
        put(
            "observations",
            Tensor::from_slice(&self.observations[..n * od], (n, od), dev)?,
        );
        put(
            "next_observations",
            Tensor::from_slice(&self.next_observations[..n * od], (n, od), dev)?,
        );
        put(
            "actions",
            Tensor::from_slice(&self.actions[..n * ad], (n, ad), dev)?,
        );
        put("rewards", Tensor::from_slice(&self.rewards[..n], n, dev)?);
        put("dones", Tensor::from_slice(&self.dones[..n], n, dev)?);
        put("position", Tensor::new(&[self.position as i64], dev)?);
        put("full", Tensor::new(&[self.full as u8], dev)?);
        Ok(out)
    }

    /// Restores transitions saved by [`Self::state`] into this buffer, which needs the same
    /// dimensions and room for them. Everything is checked before anything changes; errors name
    /// the tensor.
    pub fn load_state(
        &mut self,
        state: &HashMap<String, Tensor>,
        prefix: &str,
    ) -> Result<(), String> {
        let get = |name: &str| {
            let key = format!("{prefix}{name}");
            state
                .get(&key)
                .map(|t| (key.clone(), t))
                .ok_or_else(|| format!("the training state lacks `{key}`"))
        };
        let (key, rewards) = get("rewards")?;
        let n = match rewards.dims() {
            &[n] => n,
            d => return Err(format!("`{key}` has shape {d:?}, expected one dimension")),
        };
        // Rows of `cols` values each, as f32.
        let rows = |name: &str, cols: Option<usize>| -> Result<Vec<f32>, String> {
            let (key, t) = get(name)?;
            let want: Vec<usize> = cols.map_or(vec![n], |c| vec![n, c]);
            if t.dims() != want.as_slice() {
                return Err(format!(
                    "`{key}` has shape {:?}, expected {want:?}",
                    t.dims()
                ));
            }
            t.flatten_all()
                .and_then(|t| t.to_dtype(candle_core::DType::F32))
                .and_then(|t| t.to_vec1::<f32>())
                .map_err(|e| format!("`{key}`: {e}"))
        };
        let observations = rows("observations", Some(self.obs_dim))?;
        let next_observations = rows("next_observations", Some(self.obs_dim))?;
        let actions = rows("actions", Some(self.act_dim))?;
        let rewards = rows("rewards", None)?;
        let dones = rows("dones", None)?;
        let scalar = |name: &str| -> Result<i64, String> {
            let (key, t) = get(name)?;
            match t
                .to_dtype(candle_core::DType::I64)
                .and_then(|t| t.to_vec1::<i64>())
            {
                Ok(v) if v.len() == 1 => Ok(v[0]),
                _ => Err(format!("`{key}` must hold one integer")),
            }
        };
        let position = scalar("position")?;
        let full = scalar("full")? != 0;
        // A full buffer holds `capacity` transitions and writes anywhere; a filling one writes
        // right after its last transition.
        let consistent = if full {
            n == self.capacity && (0..n as i64).contains(&position)
        } else {
            n < self.capacity && position == n as i64
        };
        if !consistent {
            return Err(format!(
                "the saved replay buffer ({n} transitions, position {position}, full {full}) \
                 does not fit this buffer of capacity {}",
                self.capacity
            ));
        }
        let (od, ad) = (self.obs_dim, self.act_dim);
        self.observations[..n * od].copy_from_slice(&observations);
        self.next_observations[..n * od].copy_from_slice(&next_observations);
        self.actions[..n * ad].copy_from_slice(&actions);
        self.rewards[..n].copy_from_slice(&rewards);
        self.dones[..n].copy_from_slice(&dones);
        self.position = position as usize;
        self.full = full;
        Ok(())
    }

    /// Samples `batch` transitions uniformly with replacement into `out`.
    pub fn sample_into(&self, batch: usize, rng: &mut impl Rng, out: &mut ReplaySample) {
        let n = self.len();
        assert!(n > 0, "sampling an empty replay buffer");
        out.observations.clear();
        out.next_observations.clear();
        out.actions.clear();
        out.rewards.clear();
        out.dones.clear();
        for _ in 0..batch {
            let i = rng.random_range(0..n);
            out.observations
                .extend_from_slice(&self.observations[i * self.obs_dim..(i + 1) * self.obs_dim]);
            out.next_observations.extend_from_slice(
                &self.next_observations[i * self.obs_dim..(i + 1) * self.obs_dim],
            );
            out.actions
                .extend_from_slice(&self.actions[i * self.act_dim..(i + 1) * self.act_dim]);
            out.rewards.push(self.rewards[i]);
            out.dones.push(self.dones[i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn gae_matches_a_hand_computation_across_an_episode_boundary() {
        // One env, 3 steps; an episode starts at step 2.
        let mut buf = RolloutBuffer::new(3, 1, 1, 1);
        buf.push(&[0.0], &[0.0], &[1.0], &[true], &[0.5], &[0.0], &[]);
        buf.push(&[0.0], &[0.0], &[2.0], &[false], &[0.4], &[0.0], &[]);
        buf.push(&[0.0], &[0.0], &[3.0], &[true], &[0.3], &[0.0], &[]);
        let (g, l) = (0.9f32, 0.8f32);
        buf.compute_returns_and_advantages(&[0.2], &[false], g, l);
        let d2 = 3.0 + g * 0.2 - 0.3;
        let a2 = d2;
        let d1 = 2.0 - 0.4; // next step starts a new episode: no bootstrap
        let a1 = d1;
        let d0 = 1.0 + g * 0.4 - 0.5;
        let a0 = d0 + g * l * a1;
        for (got, want) in buf.advantages.iter().zip([a0, a1, a2]) {
            assert!((got - want).abs() < 1e-6, "{got} vs {want}");
        }
        assert!((buf.returns[0] - (a0 + 0.5)).abs() < 1e-6);
        // A terminal last observation cuts the bootstrap.
        buf.compute_returns_and_advantages(&[100.0], &[true], g, l);
        assert!((buf.advantages[2] - (3.0 - 0.3)).abs() < 1e-6);
    }

    #[test]
    fn replay_buffer_wraps_and_samples_stored_transitions() {
        let mut buf = ReplayBuffer::new(4, 2, 1);
        for i in 0..6 {
            let x = i as f32;
            buf.push(&[x, x], &[x], x, &[x + 1.0, x + 1.0], i % 2 == 0);
        }
        assert_eq!(buf.len(), 4);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
        let mut sample = ReplaySample::default();
        buf.sample_into(64, &mut rng, &mut sample);
        for k in 0..64 {
            let r = sample.rewards[k];
            assert!(
                (2.0..=5.0).contains(&r),
                "overwritten transition {r} sampled"
            );
            assert_eq!(sample.observations[2 * k], r);
            assert_eq!(sample.next_observations[2 * k], r + 1.0);
            assert_eq!(sample.dones[k], if (r as i32) % 2 == 0 { 1.0 } else { 0.0 });
        }
    }
    #[test]
    fn replay_buffer_state_round_trips_and_a_misfit_changes_nothing() {
        let push = |buf: &mut ReplayBuffer, count: usize| {
            for i in 0..count {
                let x = i as f32;
                buf.push(&[x, -x], &[0.5 * x], x, &[x + 1.0, 0.0], i % 3 == 0);
            }
        };
        let same = |a: &ReplayBuffer, b: &ReplayBuffer| {
            let n = a.len();
            assert_eq!((a.position, a.full, n), (b.position, b.full, b.len()));
            assert_eq!(a.observations[..2 * n], b.observations[..2 * n]);
            assert_eq!(a.next_observations[..2 * n], b.next_observations[..2 * n]);
            assert_eq!(a.actions[..n], b.actions[..n]);
            assert_eq!(a.rewards[..n], b.rewards[..n]);
            assert_eq!(a.dones[..n], b.dones[..n]);
        };
        // A wrapped (full) buffer.
        let mut full = ReplayBuffer::new(4, 2, 1);
        push(&mut full, 6);
        let state = full.state("r.").unwrap();
        assert_eq!(state["r.observations"].dims(), &[4, 2]);
        let mut restored = ReplayBuffer::new(4, 2, 1);
        restored.load_state(&state, "r.").unwrap();
        same(&full, &restored);
        // A filling buffer saves only its filled part and fits a larger buffer, not a smaller.
        let mut part = ReplayBuffer::new(8, 2, 1);
        push(&mut part, 3);
        let state = part.state("r.").unwrap();
        assert_eq!(state["r.rewards"].dims(), &[3]);
        let mut larger = ReplayBuffer::new(16, 2, 1);
        larger.load_state(&state, "r.").unwrap();
        same(&part, &larger);
        larger.push(&[9.0, 9.0], &[9.0], 9.0, &[9.0, 9.0], false);
        assert_eq!(larger.len(), 4);
        let mut small = ReplayBuffer::new(3, 2, 1);
        push(&mut small, 5);
        let before = small.clone();
        let err = small.load_state(&state, "r.").unwrap_err();
        assert!(err.contains("capacity 3"), "{err}");
        same(&before, &small);
        // A missing or mis-shaped tensor is named.
        let mut broken = state.clone();
        broken.remove("r.dones");
        assert!(
            larger
                .load_state(&broken, "r.")
                .unwrap_err()
                .contains("`r.dones`")
        );
        let mut broken = state.clone();
        broken.insert(
            "r.actions".into(),
            Tensor::zeros((3, 2), candle_core::DType::F32, &candle_core::Device::Cpu).unwrap(),
        );
        assert!(
            larger
                .load_state(&broken, "r.")
                .unwrap_err()
                .contains("`r.actions`")
        );
    }
}
