//! End-to-end PPO on camera images, asymmetric (Pinto et al. 2018): the actor is a
//! [`PixelActor`] (camera images and the arm's own readings) with a state-independent log
//! standard deviation; the critic is an MLP on the simulator's privileged state
//! (`info.privileged`, normalised by running statistics), which the actor never reads. Each has
//! its own Adam. The clipped objective's gradient with respect to the Gaussian's mean is
//! written out below and runs back through the actor's written-out passes; the candle-autograd
//! CNN was 14× slower (docs/benchmarks.md, "The camera policy's CNN").
//!
//! `fairgrasp train` runs it when the config has `[pixel_ppo]`, with the `[ppo]` settings
//! (`net_arch` and `activation` shape the critic). The other way to a camera policy,
//! distillation from a state teacher, is [`crate::distill`].

use super::{PpoConfig, PrivilegedState};
use crate::buffers::RolloutBuffer;
use crate::distributions::log_prob_term;
use crate::error::{Result, RlError};
use crate::kernels::mlp::{self, LayerParams, MlpBuffers, VarValues};
use crate::nn::{Activation, Adam, Mlp};
use crate::policies::pixel_actor::{PixelActor, PixelActorConfig, PixelCache};
use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use fairgrasp_env::VectorEnv;
use fairgrasp_env::random::standard_normal;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::ops::ControlFlow;
use std::time::Instant;

/// The `[pixel_ppo]` settings (the PPO ones are `[ppo]`'s).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PixelPpoConfig {
    /// The actor's networks.
    pub actor: PixelActorConfig,
    /// Held-out episodes the trained policy plays at the end.
    pub eval_episodes: u32,
}

impl Default for PixelPpoConfig {
    fn default() -> Self {
        Self {
            actor: PixelActorConfig::default(),
            eval_episodes: 100,
        }
    }
}

/// What one iteration (a rollout and its update) did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PixelIteration {
    /// Environment steps so far (all environments).
    pub timesteps: u64,
    /// Episodes that ended in the rollout, and how many succeeded.
    pub episodes: u32,
    /// See [`Self::episodes`].
    pub successes: u32,
    /// Mean return of those episodes (the environment's own reward units) and the share that
    /// ever grasped the object (the task's `grasped` extra; 0 where it has none).
    pub mean_return: f32,
    /// See [`Self::mean_return`].
    pub grasped: f32,
    /// Mean clipped surrogate loss, value loss and approximate KL of the last epoch.
    pub policy_loss: f32,
    /// See [`Self::policy_loss`].
    pub value_loss: f32,
    /// See [`Self::policy_loss`].
    pub approx_kl: f32,
    /// Mean standard deviation of the Gaussian.
    pub std: f32,
    /// Seconds stepping the environments (physics and rendering).
    pub env_seconds: f64,
    /// Seconds of the actor's and critic's forward passes during the rollout.
    pub act_seconds: f64,
    /// Seconds of the update (forward and backward passes, Adam).
    pub update_seconds: f64,
    /// The actor's part of the update: its forward passes, and its backward passes with
    /// Adam's steps (the rest is the critic's and the loss's).
    pub forward_seconds: f64,
    /// See [`Self::forward_seconds`].
    pub backward_seconds: f64,
}

/// The value network on the normalised privileged state.
struct Critic {
    mlp: Mlp,
    adam: Adam,
    /// Adam's variable order as indices into the pass order (`l0.weight`, `l0.bias`, …).
    order: Vec<usize>,
    buffers: MlpBuffers,
    grads: Vec<(Vec<f32>, Vec<f32>)>,
}

impl Critic {
    fn new(input: usize, config: &PpoConfig, rng: &mut ChaCha8Rng) -> Result<Self> {
        if config.activation != Activation::Tanh {
            return Err(RlError::Config {
                key: "ppo.activation".into(),
                problem: "the camera policy's critic runs on the written-out tanh MLP: \"tanh\""
                    .into(),
            });
        }
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
        let mlp = Mlp::new(&vb, input, &config.net_arch, 1, Activation::Tanh, 1.0)?;
        mlp.init_weights(&varmap, rng)?;
        let adam = Adam::new(&varmap, config.learning_rate)?;
        let layers = config.net_arch.len() + 1;
        let names: Vec<String> = (0..layers)
            .flat_map(|l| [format!("l{l}.weight"), format!("l{l}.bias")])
            .collect();
        let order = adam
            .vars()
            .map(|(name, _)| names.iter().position(|n| n == name))
            .collect::<Option<_>>()
            .ok_or_else(|| RlError::Other("the critic's variables are not its layers".into()))?;
        Ok(Self {
            mlp,
            adam,
            order,
            buffers: MlpBuffers::default(),
            grads: vec![(Vec::new(), Vec::new()); layers],
        })
    }

    /// The values of `batch` rows of `x`.
    fn values(&mut self, x: &[f32], batch: usize) -> Result<Vec<f32>> {
        let tensors = self.mlp.layer_tensors();
        let values = VarValues::new(tensors.iter().flat_map(|(w, b)| [*w, *b]));
        let layers = mlp::layers_from(&values, &tensors, 0)?;
        mlp::forward(&layers, x, batch, &mut self.buffers);
        Ok(self.buffers.outputs.last().cloned().unwrap_or_default())
    }

    /// One Adam step on `coef · mean((V − returns)²)`; returns the mean squared error.
    fn step(&mut self, x: &[f32], returns: &[f32], coef: f32, max_norm: f64) -> Result<f32> {
        let batch = returns.len();
        let n = batch as f32;
        let mut loss = 0.0f64;
        {
            // The values' read guards must be gone before Adam writes the variables.
            let tensors = self.mlp.layer_tensors();
            let values = VarValues::new(tensors.iter().flat_map(|(w, b)| [*w, *b]));
            let layers: Vec<LayerParams> = mlp::layers_from(&values, &tensors, 0)?;
            mlp::forward(&layers, x, batch, &mut self.buffers);
            let out = self.buffers.outputs.last().expect("forward ran");
            let grad: Vec<f32> = (out.iter().zip(returns))
                .map(|(v, r)| {
                    loss += ((v - r) * (v - r)) as f64;
                    coef * 2.0 * (v - r) / n
                })
                .collect();
            mlp::backward(&layers, x, batch, &grad, &mut self.buffers, &mut self.grads);
        }
        let flat: Vec<&[f32]> = (self.grads.iter())
            .flat_map(|(w, b)| [w.as_slice(), b.as_slice()])
            .collect();
        let sorted: Vec<Option<&[f32]>> = self.order.iter().map(|&i| Some(flat[i])).collect();
        self.adam.step_with(&sorted, max_norm)?;
        Ok((loss / n as f64) as f32)
    }
}

/// One minibatch gathered from the rollout.
#[derive(Default)]
struct Minibatch {
    states: Vec<f32>,
    images: Vec<u8>,
    critic: Vec<f32>,
    actions: Vec<f32>,
    log_probs: Vec<f32>,
    advantages: Vec<f32>,
    returns: Vec<f32>,
}

impl Minibatch {
    fn gather(&mut self, b: &RolloutBuffer, rows: &[usize], normalize_advantage: bool) {
        let (od, ad, pd, il) = (b.obs_dim, b.act_dim, b.privileged_dim, b.image_len);
        self.states.clear();
        self.images.clear();
        self.critic.clear();
        self.actions.clear();
        self.log_probs.clear();
        self.advantages.clear();
        self.returns.clear();
        for &i in rows {
            self.states
                .extend_from_slice(&b.observations[i * od..(i + 1) * od]);
            self.images
                .extend_from_slice(&b.images[i * il..(i + 1) * il]);
            self.critic
                .extend_from_slice(&b.privileged[i * pd..(i + 1) * pd]);
            self.actions
                .extend_from_slice(&b.actions[i * ad..(i + 1) * ad]);
            self.log_probs.push(b.log_probs[i]);
            self.advantages.push(b.advantages[i]);
            self.returns.push(b.returns[i]);
        }
        if normalize_advantage && rows.len() > 1 {
            let n = rows.len() as f32;
            let mean = self.advantages.iter().sum::<f32>() / n;
            let var = self
                .advantages
                .iter()
                .map(|a| (a - mean).powi(2))
                .sum::<f32>()
                / (n - 1.0);
            let std = var.sqrt() + 1e-8;
            for a in &mut self.advantages {
                *a = (*a - mean) / std;
            }
        }
    }
}

/// The clipped surrogate's value and gradient for one minibatch: the loss
/// `−mean(min(r·A, clip(r, 1±ε)·A)) − c_e·H` with `r = exp(log π(a) − log π_old(a))`. Writes
/// the gradient with respect to the means into `d_means`, adds the log standard deviation's
/// into `d_log_std`; returns (loss, approximate KL).
#[allow(clippy::too_many_arguments)]
fn surrogate(
    means: &[f32],
    log_std: &[f32],
    mb: &Minibatch,
    clip: f32,
    ent_coef: f32,
    d_means: &mut Vec<f32>,
    d_log_std: &mut [f32],
) -> (f32, f32) {
    let ad = log_std.len();
    let n = mb.log_probs.len() as f32;
    d_means.clear();
    d_means.resize(means.len(), 0.0);
    let (mut loss, mut kl) = (0.0f64, 0.0f64);
    for (i, (old, adv)) in mb.log_probs.iter().zip(&mb.advantages).enumerate() {
        let row = i * ad..(i + 1) * ad;
        let z: Vec<f32> = (mb.actions[row.clone()].iter().zip(&means[row.clone()]))
            .zip(log_std)
            .map(|((a, m), s)| (a - m) * (-s).exp())
            .collect();
        let log_prob: f32 = z
            .iter()
            .zip(log_std)
            .map(|(z, s)| log_prob_term(*z, *s))
            .sum();
        let log_ratio = log_prob - old;
        let ratio = log_ratio.exp();
        let unclipped = ratio * adv;
        let clipped = ratio.clamp(1.0 - clip, 1.0 + clip) * adv;
        loss -= unclipped.min(clipped) as f64;
        kl += ((ratio - 1.0) - log_ratio) as f64;
        // The min takes the unclipped term, or the clipped one where the clip is inactive.
        let active = unclipped <= clipped || (1.0 - clip..=1.0 + clip).contains(&ratio);
        if !active {
            continue;
        }
        // d loss / d log π = −A·r / n; d log π / d μ = z / σ; d log π / d log σ = z² − 1.
        let g = -adv * ratio / n;
        for j in 0..ad {
            d_means[i * ad + j] = g * z[j] * (-log_std[j]).exp();
            d_log_std[j] += g * (z[j] * z[j] - 1.0);
        }
    }
    // Entropy Σ (log σ + ½ + ½ ln 2π): its gradient per log σ is 1.
    for d in d_log_std.iter_mut() {
        *d -= ent_coef;
    }
    let entropy: f32 = log_std.iter().map(|s| s + 1.418_938_5).sum();
    (
        (loss / n as f64) as f32 - ent_coef * entropy,
        (kl / n as f64) as f32,
    )
}

/// The least standard deviation the actor's state standardisation divides by (the state's own
/// units: radians, metres, the gripper's opening): a value the first rollout hardly moved
/// (the gripper, before any grasp) would otherwise be scaled by up to 1,000 when it does move,
/// and the update blow up (an approximate KL of 24 at 16k steps with a floor of 1e-3).
const STATE_STD_FLOOR: f32 = 0.05;

/// Recomputes the stored actions' log-probabilities under `actor` and `log_std`.
fn relabel_log_probs(
    actor: &PixelActor,
    buffer: &mut RolloutBuffer,
    log_std: &[f32],
    cache: &mut PixelCache,
) -> Result<()> {
    let (od, ad, il) = (buffer.obs_dim, buffer.act_dim, buffer.image_len);
    let rows = buffer.len();
    for start in (0..rows).step_by(256) {
        let end = (start + 256).min(rows);
        let means = actor.forward(
            &buffer.observations[start * od..end * od],
            &buffer.images[start * il..end * il],
            end - start,
            cache,
        )?;
        for (i, lp) in buffer.log_probs[start..end].iter_mut().enumerate() {
            let row = (start + i) * ad;
            *lp = (0..ad)
                .map(|j| {
                    let z = (buffer.actions[row + j] - means[i * ad + j]) * (-log_std[j]).exp();
                    log_prob_term(z, log_std[j])
                })
                .sum();
        }
    }
    Ok(())
}

/// Trains a camera policy with PPO for `total_timesteps` steps of `envs`, which must give
/// camera images and privileged state. `on_iteration` sees each iteration and may stop the run.
pub fn train_pixel_ppo<V: VectorEnv>(
    envs: &mut V,
    ppo: &PpoConfig,
    config: &PixelPpoConfig,
    total_timesteps: u64,
    seed: u64,
    on_iteration: &mut dyn FnMut(&PixelIteration, &PixelActor) -> ControlFlow<()>,
) -> Result<PixelActor> {
    let images = envs.image_space().cloned().ok_or_else(|| RlError::Config {
        key: "env.camera.mode".into(),
        problem: "[pixel_ppo] needs camera images: set it to \"rgb+state\" (or depth, rgbd)".into(),
    })?;
    let pd = envs.privileged_dim();
    if pd == 0 {
        return Err(RlError::Config {
            key: "env.readings.privileged".into(),
            problem: "[pixel_ppo]'s critic reads the privileged state: set it to true".into(),
        });
    }
    let (n, state_dim, act_dim) = (envs.num_envs(), envs.obs_dim(), envs.act_dim());
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut actor =
        PixelActor::new(&config.actor, &images, state_dim, act_dim, &mut rng).map_err(|p| {
            RlError::Config {
                key: "pixel_ppo.actor".into(),
                problem: p,
            }
        })?;
    let mut adam = Adam::new(actor.varmap(), ppo.learning_rate)?;
    let log_std_map = VarMap::new();
    let log_std_var = Var::from_tensor(&Tensor::full(ppo.log_std_init, act_dim, &Device::Cpu)?)?;
    log_std_map
        .data()
        .lock()
        .expect("varmap lock")
        .insert("log_std".into(), log_std_var.clone());
    let mut log_std_adam = Adam::new(&log_std_map, ppo.learning_rate)?;
    let mut critic = Critic::new(pd, ppo, &mut rng)?;
    let mut privileged = PrivilegedState::new(pd);
    let mut buffer = RolloutBuffer::new(ppo.n_steps, n, state_dim, act_dim)
        .with_privileged(pd)
        .with_images(images.len());
    let mut cache = PixelCache::default();
    let mut mb = Minibatch::default();
    let (mut d_means, mut actions, mut clipped) = (Vec::new(), vec![0.0; n * act_dim], Vec::new());

    envs.reset(Some(seed))?;
    privileged.set_rows(envs.reset_infos().iter())?;
    let mut starts = vec![true; n];
    let mut timesteps = 0u64;
    while timesteps < total_timesteps {
        let mut it = PixelIteration::default();
        let log_std: Vec<f32> = log_std_var.as_tensor().to_vec1()?;
        buffer.clear();
        for _ in 0..ppo.n_steps {
            let started = Instant::now();
            let states = envs.observations().to_vec();
            let frames = envs.images().to_vec();
            let means = actor.forward(&states, &frames, n, &mut cache)?;
            let values = critic.values(&privileged.rows, n)?;
            let mut log_probs = vec![0.0f32; n];
            for i in 0..n {
                for j in 0..act_dim {
                    let z = standard_normal(&mut rng);
                    actions[i * act_dim + j] = means[i * act_dim + j] + z * log_std[j].exp();
                    log_probs[i] += log_prob_term(z, log_std[j]);
                }
            }
            clipped.clear();
            clipped.extend(actions.iter().map(|a| a.clamp(-1.0, 1.0)));
            it.act_seconds += started.elapsed().as_secs_f64();
            let started = Instant::now();
            let step = envs.step(&clipped)?;
            it.env_seconds += started.elapsed().as_secs_f64();
            buffer.push_images(&frames);
            let rows = privileged.rows.clone();
            buffer.push(
                &states,
                &actions,
                step.rewards,
                &starts,
                &values,
                &log_probs,
                &rows,
            );
            for (i, start) in starts.iter_mut().enumerate() {
                *start = step.terminated[i] || step.truncated[i];
                if let Some(end) = &step.episode_ends[i] {
                    it.episodes += 1;
                    it.successes += u32::from(step.infos[i].success);
                    it.mean_return += end.episode.episode_return as f32;
                    it.grasped += end.episode.max_extras.get("grasped").unwrap_or(0.0);
                    if step.truncated[i] && !step.terminated[i] {
                        // Bootstrap the cut episode from its last state's value.
                        let mut x = Vec::new();
                        privileged.normalize_into(privileged.of(i, &step.infos[i])?, &mut x);
                        let v = critic.values(&x, 1)?[0];
                        buffer.add_to_last_reward(i, ppo.gamma * v);
                    }
                }
            }
            privileged.advance(&step)?;
        }
        if timesteps == 0 {
            // The first rollout's states fix the actor's standardisation of its state input
            // (the states at reset alone hardly vary); its actions' log-probabilities are
            // recomputed under it, so the first update starts from the policy it changes.
            actor.fit_state_scale(&buffer.observations, STATE_STD_FLOOR);
            relabel_log_probs(&actor, &mut buffer, &log_std, &mut cache)?;
        }
        if it.episodes > 0 {
            it.mean_return /= it.episodes as f32;
            it.grasped /= it.episodes as f32;
        }
        timesteps += (ppo.n_steps * n) as u64;
        let last_values = critic.values(&privileged.rows, n)?;
        buffer.compute_returns_and_advantages(&last_values, &starts, ppo.gamma, ppo.gae_lambda);

        let started = Instant::now();
        let (forward_before, backward_before) = (cache.forward_seconds, cache.backward_seconds);
        let progress_remaining = 1.0 - timesteps as f64 / total_timesteps as f64;
        let lr = ppo.lr_schedule.at(ppo.learning_rate, progress_remaining);
        (adam.lr, log_std_adam.lr, critic.adam.lr) = (lr, lr, lr);
        let mut order: Vec<usize> = (0..buffer.len()).collect();
        'epochs: for _ in 0..ppo.n_epochs {
            order.shuffle(&mut rng);
            let (mut p_sum, mut v_sum, mut kl_sum, mut count) = (0.0, 0.0, 0.0, 0);
            for rows in order.chunks(ppo.batch_size) {
                mb.gather(&buffer, rows, ppo.normalize_advantage);
                let log_std: Vec<f32> = log_std_var.as_tensor().to_vec1()?;
                let mut d_log_std = vec![0.0f32; act_dim];
                let mut kl = 0.0;
                let mut loss = |means: &[f32], d: &mut Vec<f32>| {
                    let (l, k) = surrogate(
                        means,
                        &log_std,
                        &mb,
                        ppo.clip_range,
                        ppo.ent_coef,
                        &mut d_means,
                        &mut d_log_std,
                    );
                    d.clone_from(&d_means);
                    kl = k;
                    l
                };
                let p = actor.step_on(
                    &mut adam,
                    &mb.states,
                    &mb.images,
                    rows.len(),
                    &mut cache,
                    ppo.max_grad_norm,
                    &mut loss,
                )?;
                log_std_adam.step_with(&[Some(&d_log_std)], ppo.max_grad_norm)?;
                let v = critic.step(&mb.critic, &mb.returns, ppo.vf_coef, ppo.max_grad_norm)?;
                (p_sum, v_sum, kl_sum, count) = (p_sum + p, v_sum + v, kl_sum + kl, count + 1);
                if ppo.target_kl.is_some_and(|t| kl > 1.5 * t) {
                    break 'epochs;
                }
            }
            let c = count.max(1) as f32;
            (it.policy_loss, it.value_loss, it.approx_kl) = (p_sum / c, v_sum / c, kl_sum / c);
        }
        it.update_seconds = started.elapsed().as_secs_f64();
        it.forward_seconds = cache.forward_seconds - forward_before;
        it.backward_seconds = cache.backward_seconds - backward_before;
        it.timesteps = timesteps;
        let log_std: Vec<f32> = log_std_var.as_tensor().to_vec1()?;
        it.std = log_std.iter().map(|s| s.exp()).sum::<f32>() / act_dim as f32;
        if on_iteration(&it, &actor).is_break() {
            break;
        }
    }
    Ok(actor)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::distill::tests::envs;
    use fairgrasp_env::ObsMode;

    fn small() -> (PpoConfig, PixelPpoConfig) {
        let ppo = PpoConfig {
            n_steps: 6,
            batch_size: 4,
            n_epochs: 2,
            net_arch: vec![16],
            ..PpoConfig::default()
        };
        let pixel = PixelPpoConfig {
            actor: PixelActorConfig {
                features: 8,
                net_arch: vec![16],
                ..PixelActorConfig::default()
            },
            eval_episodes: 1,
        };
        (ppo, pixel)
    }

    fn run(seed: u64) -> (Vec<PixelIteration>, Vec<Vec<f32>>) {
        let (ppo, pixel) = small();
        let mut its = Vec::new();
        let mut watch = |it: &PixelIteration, _: &PixelActor| {
            its.push(it.clone());
            ControlFlow::Continue(())
        };
        let mut venv = envs(ObsMode::RgbState);
        let actor = train_pixel_ppo(&mut venv, &ppo, &pixel, 24, seed, &mut watch).unwrap();
        let weights = actor.weights();
        let mut names: Vec<&String> = weights.keys().collect();
        names.sort();
        let weights = (names.iter())
            .map(|n| weights[*n].flatten_all().unwrap().to_vec1::<f32>().unwrap())
            .collect();
        (its, weights)
    }

    #[test]
    fn a_seeded_run_repeats_bit_for_bit_and_its_updates_move_the_policy() {
        let (its, weights) = run(5);
        let steps: Vec<u64> = its.iter().map(|i| i.timesteps).collect();
        assert_eq!(steps, [12, 24], "two iterations of 6 steps of 2 envs");
        for it in &its {
            assert!(it.approx_kl > 0.0, "the updates changed the policy: {it:?}");
            assert!(
                it.value_loss.is_finite() && it.policy_loss.is_finite(),
                "{it:?}"
            );
        }
        assert_eq!(run(5).1, weights, "the same seed trains the same weights");
        assert_ne!(run(6).1, weights, "another seed, other weights");
    }

    #[test]
    fn an_env_without_camera_images_is_refused_by_its_key() {
        let (ppo, pixel) = small();
        let mut venv = envs(ObsMode::State);
        let err = train_pixel_ppo(&mut venv, &ppo, &pixel, 24, 1, &mut |_, _| {
            ControlFlow::Continue(())
        })
        .err()
        .expect("a state env is refused");
        assert!(err.to_string().contains("env.camera.mode"), "{err}");
    }

    fn minibatch(actions: Vec<f32>, log_probs: Vec<f32>, advantages: Vec<f32>) -> Minibatch {
        Minibatch {
            actions,
            log_probs,
            advantages,
            ..Minibatch::default()
        }
    }

    #[test]
    fn the_surrogates_gradients_match_finite_differences() {
        let log_std = [-0.3f32, 0.2];
        let means = [0.1f32, -0.2, 0.4, 0.3, -0.5, 0.0];
        let actions = vec![0.3, -0.1, 0.2, 0.9, -0.4, 0.2];
        // Old log-probabilities near the new ones, so some ratios fall inside the clip and
        // one (the third) outside it.
        let mut old = Vec::new();
        for i in 0..3 {
            let lp: f32 = (0..2)
                .map(|j| {
                    let z = (actions[i * 2 + j] - means[i * 2 + j]) * (-log_std[j]).exp();
                    log_prob_term(z, log_std[j])
                })
                .sum();
            old.push(lp + [0.05, -0.1, -0.6][i]);
        }
        let mb = minibatch(actions, old, vec![1.0, -0.5, 2.0]);
        let (mut d_means, mut d_log_std) = (Vec::new(), [0.0f32; 2]);
        surrogate(
            &means,
            &log_std,
            &mb,
            0.2,
            0.01,
            &mut d_means,
            &mut d_log_std,
        );
        let loss = |m: &[f32], s: &[f32]| {
            let (mut d, mut ds) = (Vec::new(), [0.0f32; 2]);
            surrogate(m, s, &mb, 0.2, 0.01, &mut d, &mut ds).0
        };
        let eps = 1e-3;
        for k in 0..6 {
            let (mut up, mut down) = (means, means);
            up[k] += eps;
            down[k] -= eps;
            let numeric = (loss(&up, &log_std) - loss(&down, &log_std)) / (2.0 * eps);
            assert!(
                (numeric - d_means[k]).abs() < 2e-3,
                "mean {k}: {numeric} vs {}",
                d_means[k]
            );
        }
        // The third sample's ratio is clipped: no gradient through its mean.
        assert_eq!(&d_means[4..], &[0.0, 0.0]);
        for j in 0..2 {
            let (mut up, mut down) = (log_std, log_std);
            up[j] += eps;
            down[j] -= eps;
            let numeric = (loss(&means, &up) - loss(&means, &down)) / (2.0 * eps);
            assert!(
                (numeric - d_log_std[j]).abs() < 2e-3,
                "log std {j}: {numeric} vs {}",
                d_log_std[j]
            );
        }
    }
}
