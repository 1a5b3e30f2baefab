//! What the training driver needs from a learning algorithm (PPO, SAC): collect experience and
//! learn, act for evaluation, and hand over its state for models and checkpoints.
//!
//! Like SB3's `BaseAlgorithm`, one driver ([`crate::train`]) runs evaluation, checkpoints, logs
//! and resume for every algorithm; an algorithm only knows how to learn.

use crate::error::{Result, RlError};
use candle_core::Tensor;
use fairgrasp_env::{VecStep, VectorEnv};
use rand_chacha::ChaCha8Rng;
use std::collections::HashMap;

/// Named tensors, as stored in a safetensors file.
pub type TensorMap = HashMap<String, Tensor>;

/// A learning algorithm driven by [`crate::train`].
pub trait Algorithm {
    /// Short lowercase name (`"ppo"`, `"sac"`), stored in saved models.
    fn name(&self) -> &'static str;

    /// Environment steps taken so far (all environments together).
    fn num_timesteps(&self) -> u64;

    /// Log the training scalars at most once per this many environment steps (0: after every
    /// iteration). Off-policy learners iterate once per vector step and log every 1,000.
    fn log_interval(&self) -> u64 {
        0
    }

    /// Sets the step counter (when resuming from a checkpoint).
    fn set_num_timesteps(&mut self, steps: u64);

    /// One iteration of the algorithm: steps `venv` (from its current observations) and learns.
    /// `progress_remaining` goes from 1 to 0 over training (for schedules); `on_step` sees every
    /// vector step (for episode statistics). Returns the `train/*` scalars to log, if it learnt.
    fn learn_iteration<V: VectorEnv>(
        &mut self,
        venv: &mut V,
        progress_remaining: f64,
        on_step: &mut dyn FnMut(&VecStep<'_>),
    ) -> Result<Vec<(&'static str, f32)>>;

    /// Actions for a batch of observations: the distribution's mode when `deterministic`.
    fn predict(&mut self, obs: &[f32], deterministic: bool) -> Result<Vec<f32>>;

    /// The weights of every network (the `model.safetensors` of a saved model).
    fn weights(&self) -> Result<TensorMap>;

    /// Loads weights saved by [`Self::weights`]; errors name a missing or mis-shaped tensor.
    fn load_weights(&mut self, weights: &TensorMap) -> Result<()>;

    /// Everything else that resuming needs: optimiser moments, entropy coefficient, replay
    /// buffer… (the `training_state.safetensors` of a checkpoint).
    fn training_state(&self) -> Result<TensorMap>;

    /// Restores a state saved by [`Self::training_state`].
    fn load_training_state(&mut self, state: &TensorMap) -> Result<()>;

    /// The algorithm's random stream (saved in checkpoints so a resumed run draws on).
    fn rng_mut(&mut self) -> &mut ChaCha8Rng;
}

/// Copies `weights` into the variables of `varmap`, checking every name and shape first so that
/// a mismatched file changes nothing.
pub fn load_varmap(varmap: &candle_nn::VarMap, weights: &TensorMap) -> Result<()> {
    let data = varmap.data().lock().expect("varmap lock");
    let mut names: Vec<&String> = data.keys().collect();
    names.sort();
    for name in &names {
        let var = &data[*name];
        let t = weights
            .get(*name)
            .ok_or_else(|| RlError::Model(format!("the weights lack tensor `{name}`")))?;
        if t.dims() != var.dims() {
            return Err(RlError::Model(format!(
                "tensor `{name}` has shape {:?}, the network expects {:?}",
                t.dims(),
                var.dims()
            )));
        }
    }
    if let Some(extra) = weights.keys().find(|k| !data.contains_key(*k)) {
        return Err(RlError::Model(format!(
            "the weights hold tensor `{extra}`, which this network does not have"
        )));
    }
    for name in names {
        let t = weights[name].to_dtype(candle_core::DType::F32)?;
        data[name].set(&t)?;
    }
    Ok(())
}

/// Loads weights into groups of variables told apart by name prefix (`actor.`, `critic.`, …).
/// A tensor of no group, or a missing or mis-shaped one, is an error that names it; `scratch`
/// (groups of the same shapes, e.g. a zeroed copy of the networks) takes every group first, so
/// a mismatch in a late group leaves the earlier ones of `groups` untouched.
pub fn load_grouped(
    groups: &[(&str, &candle_nn::VarMap)],
    scratch: &[(&str, &candle_nn::VarMap)],
    weights: &TensorMap,
) -> Result<()> {
    let mut parts = vec![TensorMap::new(); groups.len()];
    for (name, t) in weights {
        let Some(g) = groups.iter().position(|(p, _)| name.starts_with(p)) else {
            return Err(RlError::Model(format!(
                "the weights hold tensor `{name}`, which this network does not have"
            )));
        };
        parts[g].insert(name.clone(), t.clone());
    }
    for ((_, varmap), part) in scratch.iter().zip(&parts) {
        load_varmap(varmap, part)?;
    }
    for ((_, varmap), part) in groups.iter().zip(&parts) {
        load_varmap(varmap, part)?;
    }
    Ok(())
}

/// The tensors of `varmap` by name, prefixed with `prefix`.
pub fn varmap_tensors(varmap: &candle_nn::VarMap, prefix: &str) -> TensorMap {
    varmap
        .data()
        .lock()
        .expect("varmap lock")
        .iter()
        .map(|(k, v)| (format!("{prefix}{k}"), v.as_tensor().clone()))
        .collect()
}

/// The state of a ChaCha8 stream as three tensors (seed bytes, stream, word position), so that
/// it rides along in a safetensors checkpoint.
pub fn rng_state(rng: &ChaCha8Rng, prefix: &str) -> Result<TensorMap> {
    let dev = candle_core::Device::Cpu;
    let seed: Vec<u32> = rng.get_seed().iter().map(|&b| b as u32).collect();
    let pos = rng.get_word_pos();
    let words = [
        (pos & 0xffff_ffff) as u32,
        ((pos >> 32) & 0xffff_ffff) as u32,
        ((pos >> 64) & 0xffff_ffff) as u32,
        ((pos >> 96) & 0xffff_ffff) as u32,
    ];
    let stream = rng.get_stream();
    let stream = [(stream & 0xffff_ffff) as u32, (stream >> 32) as u32];
    let mut out = TensorMap::new();
    out.insert(format!("{prefix}rng.seed"), Tensor::new(seed, &dev)?);
    out.insert(format!("{prefix}rng.word_pos"), Tensor::new(&words, &dev)?);
    out.insert(format!("{prefix}rng.stream"), Tensor::new(&stream, &dev)?);
    Ok(out)
}

/// Rebuilds a stream saved by [`rng_state`].
pub fn rng_from_state(state: &TensorMap, prefix: &str) -> Result<ChaCha8Rng> {
    use rand::SeedableRng;
    let get = |name: &str, len: usize| -> Result<Vec<u32>> {
        let key = format!("{prefix}rng.{name}");
        let v = state
            .get(&key)
            .ok_or_else(|| RlError::Model(format!("the training state lacks `{key}`")))?
            .to_vec1::<u32>()
            .map_err(|e| RlError::Model(format!("`{key}`: {e}")))?;
        if v.len() != len {
            return Err(RlError::Model(format!(
                "`{key}` has {} values, expected {len}",
                v.len()
            )));
        }
        Ok(v)
    };
    let seed = get("seed", 32)?;
    let mut bytes = [0u8; 32];
    for (b, v) in bytes.iter_mut().zip(&seed) {
        *b = *v as u8;
    }
    let mut rng = ChaCha8Rng::from_seed(bytes);
    let s = get("stream", 2)?;
    rng.set_stream(s[0] as u64 | (s[1] as u64) << 32);
    let w = get("word_pos", 4)?;
    rng.set_word_pos(
        w[0] as u128 | (w[1] as u128) << 32 | (w[2] as u128) << 64 | (w[3] as u128) << 96,
    );
    Ok(rng)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn rng_state_round_trips_mid_stream() {
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        for _ in 0..1001 {
            rng.random::<u32>();
        }
        let state = rng_state(&rng, "ppo.").unwrap();
        let mut restored = rng_from_state(&state, "ppo.").unwrap();
        let a: Vec<u64> = (0..50).map(|_| rng.random()).collect();
        let b: Vec<u64> = (0..50).map(|_| restored.random()).collect();
        assert_eq!(a, b);
        assert!(rng_from_state(&state, "sac.").is_err());
    }
}
