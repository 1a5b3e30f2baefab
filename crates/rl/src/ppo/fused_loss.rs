//! PPO's minibatch loss and its gradient written out, for the default actor-critic (flat
//! observations, tanh MLP heads, no value clipping), on reused buffers.
//!
//! Why: through candle's autograd one design-setting minibatch step ([64, 64] networks, 256
//! samples) ran a few hundred small tensor operations, each allocating its result: 0.94–1.28 ms
//! of CPU (1.4–2.0 ms wall on the shared 2-core host), 320 of them per update. Written out it is
//! the networks' matrix products and a few loops: 0.28–0.30 ms of CPU.
//!
//! Every value is computed as candle computed it in [`crate::ppo::Ppo::update`]'s tensor code
//! (kept as the general path), in the same order: sums through candle's
//! `VecOps::vec_reduce_sum` ([`mlp::sum`]), `x · c` as `x · (c as f32) + 0`, the gradients of `minimum`,
//! `maximum` and the broadcasts by candle's rules, and the log standard deviation's three
//! gradient contributions accumulated in candle's order. Only the networks' matrix products
//! sum in another order ([`mlp`]'s, the same on every host), so the weights it trains are the
//! tensor code's to rounding (tested in [`crate::ppo`]).

use crate::distributions::{HALF_LN_2PI, log_prob_term};
use crate::error::{Result, RlError};
use crate::kernels::mlp::{self, LayerParams, MlpBuffers, VarValues, sum};
use crate::nn::Mlp;
use candle_core::Tensor;
use fairgrasp_env::vector::LockstepPool;
use std::sync::Mutex;

/// candle's `mean_all`: the sum times `1/n` (as f32), plus 0.
fn mean(values: &[f32]) -> f32 {
    sum(values) * (1.0 / values.len() as f64) as f32 + 0.0
}

/// The loss terms of one minibatch (SB3's `train/*` scalars), before the step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MinibatchStats {
    /// Clipped surrogate loss.
    pub policy_loss: f32,
    /// Mean squared error of the values against the returns.
    pub value_loss: f32,
    /// The policy's entropy (nats), mean over the samples.
    pub entropy: f32,
    /// Approximate KL divergence of the new policy from the old, `mean((r − 1) − log r)`.
    pub approx_kl: f32,
    /// Fraction of samples whose ratio `r` lies outside 1 ± `clip_range`.
    pub clip_fraction: f32,
}

/// One minibatch's samples, row-major.
pub struct Minibatch<'a> {
    /// `batch × obs_dim`.
    pub observations: &'a [f32],
    /// What the value head reads: the observations, or with a privileged critic each
    /// observation followed by its privileged state.
    pub value_inputs: &'a [f32],
    /// `batch × act_dim`, as sampled.
    pub actions: &'a [f32],
    /// Log-probability (nats) of each action under the policy that collected it.
    pub old_log_probs: &'a [f32],
    /// Advantages as stored (normalised here when the configuration says so).
    pub advantages: &'a [f32],
    /// The value head's targets, one per sample.
    pub returns: &'a [f32],
}

/// The written-out loss and gradient, with its buffers.
///
/// The value head's passes share nothing with the policy's but the observations, so with
/// [`Self::set_threads`] above 1 they run on a second thread while this one does the policy's:
/// the update was 12–14 % of the design settings' wall time, spent on one of the two cores.
/// Design-settings PPO went from 7,934 to 8,206 env steps/s (PD arm) and from 12,890 to 13,514
/// (kinematic arm): medians of 7 alternated runs on a 2-core host.
#[derive(Default)]
pub struct FusedPpoLoss {
    policy: PolicyPart,
    value: ValuePart,
    /// The second thread (`None`: both heads on the caller's thread).
    helper: Option<LockstepPool>,
}

/// The policy head's loss terms and gradients (and `log σ`'s).
#[derive(Default)]
struct PolicyPart {
    pi: MlpBuffers,
    pi_grads: Vec<(Vec<f32>, Vec<f32>)>,
    log_std_grad: Vec<f32>,
    advantages: Vec<f32>,
    /// Per sample.
    log_ratio: Vec<f32>,
    ratio: Vec<f32>,
    scratch: Vec<f32>,
    /// Per sample and action dimension.
    grad_mean: Vec<f32>,
    z: Vec<f32>,
    diff: Vec<f32>,
}

/// What the policy part returns: [`MinibatchStats`] less the value loss.
struct PolicyStats {
    policy_loss: f32,
    entropy: f32,
    approx_kl: f32,
    clip_fraction: f32,
}

/// The value head's loss and gradients.
#[derive(Default)]
struct ValuePart {
    vf: MlpBuffers,
    vf_grads: Vec<(Vec<f32>, Vec<f32>)>,
    /// Per sample: the squared errors, then their gradients.
    grad_values: Vec<f32>,
}

/// The settings of PPO's loss that the computation reads.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossCoefficients {
    /// The policy ratio is clipped to `1 ± clip_range`.
    pub clip_range: f32,
    /// Weight of the entropy bonus.
    pub ent_coef: f32,
    /// Weight of the value loss.
    pub vf_coef: f32,
    /// Whether advantages are normalised per minibatch.
    pub normalize_advantage: bool,
}

impl FusedPpoLoss {
    /// Runs the value head on a second thread when `threads` is 2 or more (the training's
    /// `threads`); the results are the same bits either way.
    pub fn set_threads(&mut self, threads: usize) -> Result<()> {
        // 0: one per CPU, as the training's `threads` reads it.
        let threads = match threads {
            0 => std::thread::available_parallelism().map_or(1, |p| p.get()),
            t => t,
        };
        if threads < 2 {
            self.helper = None;
        } else if self.helper.is_none() {
            self.helper = Some(LockstepPool::new(2).map_err(|e| {
                RlError::Other(format!("cannot start the PPO update's second thread: {e}"))
            })?);
        }
        Ok(())
    }

    /// The loss terms of `batch`; the loss's gradient is then [`Self::gradients`].
    pub fn compute(
        &mut self,
        (pi, vf, log_std): (&Mlp, &Mlp, &Tensor),
        config: &LossCoefficients,
        batch: &Minibatch<'_>,
    ) -> Result<MinibatchStats> {
        let act_dim = log_std.elem_count();
        let (pi_vars, vf_vars) = (pi.layer_tensors(), vf.layer_tensors());
        let values = VarValues::new(
            pi_vars
                .iter()
                .chain(&vf_vars)
                .flat_map(|(w, b)| [*w, *b])
                .chain([log_std]),
        );
        let pi_layers = mlp::layers_from(&values, &pi_vars, 0)?;
        let vf_layers = mlp::layers_from(&values, &vf_vars, 2 * pi_vars.len())?;
        let log_std = values.get(2 * (pi_vars.len() + vf_vars.len()))?;

        let Self {
            policy: policy_part,
            value: value_part,
            helper,
        } = self;
        let (p, value_loss) = match helper {
            None => (
                policy_part.compute(&pi_layers, log_std, act_dim, config, batch),
                value_part.compute(&vf_layers, batch, config.vf_coef),
            ),
            Some(pool) => {
                // Each part locks only its own head's buffers, once per call.
                let policy_cell = Mutex::new((policy_part, None));
                let value_cell = Mutex::new((value_part, 0.0));
                pool.run(&|part| {
                    if part == 0 {
                        let mut guard = policy_cell.lock().unwrap_or_else(|e| e.into_inner());
                        let stats = guard.0.compute(&pi_layers, log_std, act_dim, config, batch);
                        guard.1 = Some(stats);
                    } else {
                        let mut guard = value_cell.lock().unwrap_or_else(|e| e.into_inner());
                        guard.1 = guard.0.compute(&vf_layers, batch, config.vf_coef);
                    }
                });
                let stats = policy_cell
                    .into_inner()
                    .unwrap_or_else(|e| e.into_inner())
                    .1;
                let value_loss = value_cell.into_inner().unwrap_or_else(|e| e.into_inner()).1;
                (
                    stats.expect("part 0 ran (a panic would have been re-raised)"),
                    value_loss,
                )
            }
        };
        Ok(MinibatchStats {
            policy_loss: p.policy_loss,
            value_loss,
            entropy: p.entropy,
            approx_kl: p.approx_kl,
            clip_fraction: p.clip_fraction,
        })
    }

    /// The gradient of the last [`Self::compute`]'s loss, one per parameter named in `names`
    /// (`pi.l0.weight`, `log_std`, …), `None` for a name it does not know.
    pub fn gradients<'s>(&'s self, names: &[&str]) -> Vec<Option<&'s [f32]>> {
        names.iter().map(|name| self.grad_of(name)).collect()
    }

    /// The gradient of the parameter named `name` (`pi.l0.weight`, `log_std`, …).
    fn grad_of(&self, name: &str) -> Option<&[f32]> {
        if name == "log_std" {
            return Some(&self.policy.log_std_grad);
        }
        let (head, rest) = name.split_once('.')?;
        let (layer, kind) = rest.strip_prefix('l')?.split_once('.')?;
        let layer: usize = layer.parse().ok()?;
        let grads = match head {
            "pi" => &self.policy.pi_grads,
            "vf" => &self.value.vf_grads,
            _ => return None,
        };
        let (w, b) = grads.get(layer)?;
        match kind {
            "weight" => Some(w),
            "bias" => Some(b),
            _ => None,
        }
    }
}

impl ValuePart {
    /// The value loss `mean((V − R)²)` of `batch`, and its gradient into `vf_grads`.
    fn compute(&mut self, layers: &[LayerParams<'_>], batch: &Minibatch<'_>, vf_coef: f32) -> f32 {
        let n = batch.returns.len();
        let inv_n = (1.0 / n as f64) as f32;
        mlp::forward(layers, batch.value_inputs, n, &mut self.vf);
        let state_values = self.vf.outputs.last().expect("vf has layers");
        self.grad_values.clear();
        self.grad_values.extend(
            state_values
                .iter()
                .zip(batch.returns)
                .map(|(v, r)| (v - r) * (v - r)),
        );
        let value_loss = mean(&self.grad_values);
        let g_vl = 1.0 * vf_coef + 0.0;
        let g_sq = g_vl * inv_n + 0.0;
        for (g, (v, r)) in self
            .grad_values
            .iter_mut()
            .zip(state_values.iter().zip(batch.returns))
        {
            *g = ((v - r) * g_sq) * 2.0 + 0.0;
        }
        self.vf_grads.resize_with(layers.len(), Default::default);
        mlp::backward(
            layers,
            batch.value_inputs,
            n,
            &self.grad_values,
            &mut self.vf,
            &mut self.vf_grads,
        );
        value_loss
    }
}

impl PolicyPart {
    /// The clipped surrogate, entropy and diagnostics of `batch`, and the gradients of
    /// `policy loss − ent_coef · entropy` into `pi_grads` and `log_std_grad`.
    fn compute(
        &mut self,
        pi_layers: &[LayerParams<'_>],
        log_std: &[f32],
        act_dim: usize,
        config: &LossCoefficients,
        batch: &Minibatch<'_>,
    ) -> PolicyStats {
        let n = batch.old_log_probs.len();
        let inv_n = (1.0 / n as f64) as f32;

        // Advantages, normalised as `(A − mean) / (std + 1e-8)`.
        let adv = &mut self.advantages;
        adv.clear();
        adv.extend_from_slice(batch.advantages);
        if config.normalize_advantage && n > 1 {
            let m = mean(adv);
            self.scratch.clear();
            self.scratch.extend(adv.iter().map(|a| (a - m) * (a - m)));
            let denom = mean(&self.scratch).sqrt() * 1.0 + 1e-8f64 as f32;
            for a in adv.iter_mut() {
                *a = (*a - m) / denom;
            }
        }

        mlp::forward(pi_layers, batch.observations, n, &mut self.pi);
        let means = self.pi.outputs.last().expect("pi has layers");

        // log π(a|s): z = (a − μ)·e^{−log σ}, Σ (z² · (−½) − log σ − ½ ln 2π).
        let inv_std: Vec<f32> = log_std.iter().map(|s| (-s).exp()).collect();
        self.diff.clear();
        self.z.clear();
        self.log_ratio.clear();
        let mut terms = vec![0.0f32; act_dim];
        for i in 0..n {
            let row = i * act_dim..(i + 1) * act_dim;
            for (j, ((a, mu), t)) in batch.actions[row.clone()]
                .iter()
                .zip(&means[row])
                .zip(terms.iter_mut())
                .enumerate()
            {
                let d = a - mu;
                let z = d * inv_std[j];
                *t = log_prob_term(z, log_std[j]);
                self.diff.push(d);
                self.z.push(z);
            }
            self.log_ratio.push(sum(&terms) - batch.old_log_probs[i]);
        }
        self.ratio.clear();
        self.ratio.extend(self.log_ratio.iter().map(|r| r.exp()));

        // Clipped surrogate: −mean(min(r·A, clamp(r, 1 ± ε)·A)), candle's min/max.
        let (lo, hi) = (1.0 - config.clip_range, 1.0 + config.clip_range);
        let maximum = |a: f32, b: f32| if a < b { b } else { a };
        let minimum = |a: f32, b: f32| if a > b { b } else { a };
        self.scratch.clear();
        self.scratch
            .extend(self.ratio.iter().zip(adv.iter()).map(|(&r, &a)| {
                let clamped = minimum(maximum(r, lo), hi);
                minimum(r * a, clamped * a)
            }));
        let policy_loss = -mean(&self.scratch);
        let mask = |c: bool| if c { 1.0f32 } else { 0.0 };
        // Gradients of the mean's samples, then through the minimum and the clamp.
        let g_pl = -inv_n + 0.0;
        let mut g_log_ratio = std::mem::take(&mut self.scratch);
        for (i, g) in g_log_ratio.iter_mut().enumerate() {
            let (r, a) = (self.ratio[i], adv[i]);
            let maxed = maximum(r, lo);
            let clamped = minimum(maxed, hi);
            let (s1, s2) = (r * a, clamped * a);
            let m = minimum(s1, s2);
            let (m1, m2) = (mask(m == s1), mask(m == s2));
            let g_s1 = (m1 * g_pl) / (m2 * 1.0 + 1.0);
            let g_s2 = (m2 * g_pl) / (m1 * 1.0 + 1.0);
            let g_clamped = g_s2 * a;
            let (m3, m4) = (mask(clamped == maxed), mask(clamped == hi));
            let g_maxed = (m3 * g_clamped) / (m4 * 1.0 + 1.0);
            let (m5, m6) = (mask(maxed == r), mask(maxed == lo));
            let g_ratio = g_s1 * a + (m5 * g_maxed) / (m6 * 1.0 + 1.0);
            *g = g_ratio * r;
        }

        // Entropy Σ (log σ + ½ ln 2πe) per sample, the same for every sample.
        let ent_const = (0.5 + HALF_LN_2PI) as f32;
        terms.clear();
        terms.extend(log_std.iter().map(|s| s * 1.0 + ent_const));
        self.scratch.clear();
        self.scratch.resize(n, sum(&terms));
        let entropy = mean(&self.scratch);

        // Through log π: to the means and to log σ. log σ's gradient gathers the entropy's
        // broadcast, the `− log σ` broadcast and the `e^{−log σ}` factor, in candle's order.
        let g_ent_row = (-config.ent_coef + 0.0) * inv_n + 0.0;
        let with_entropy = config.ent_coef != 0.0;
        self.grad_mean.clear();
        self.grad_mean.resize(n * act_dim, 0.0);
        let mut g_sub = vec![0.0f32; act_dim];
        let mut g_inv_std = vec![0.0f32; act_dim];
        let mut g_ent = vec![0.0f32; act_dim];
        for (i, &g_logp) in g_log_ratio.iter().enumerate() {
            for j in 0..act_dim {
                let k = i * act_dim + j;
                g_sub[j] += 0.0 - g_logp;
                let g_zsq = g_logp * -0.5 + 0.0;
                let g_z = (self.z[k] * g_zsq) * 2.0 + 0.0;
                g_inv_std[j] += g_z * self.diff[k];
                self.grad_mean[k] = 0.0 - g_z * inv_std[j];
                if with_entropy {
                    g_ent[j] += g_ent_row;
                }
            }
        }
        self.log_std_grad.clear();
        for j in 0..act_dim {
            let g_neg = g_inv_std[j] * inv_std[j];
            let mut g = if with_entropy { 0.0 + g_ent[j] } else { 0.0 };
            g += g_sub[j];
            self.log_std_grad.push(g - g_neg);
        }

        self.pi_grads.resize_with(pi_layers.len(), Default::default);
        mlp::backward(
            pi_layers,
            batch.observations,
            n,
            &self.grad_mean,
            &mut self.pi,
            &mut self.pi_grads,
        );

        // Diagnostics, as the tensor code computes them.
        self.scratch = g_log_ratio;
        self.scratch.clear();
        self.scratch.extend(
            self.ratio
                .iter()
                .zip(&self.log_ratio)
                .map(|(r, lr)| (r * 1.0 + -1.0) - lr),
        );
        let approx_kl = mean(&self.scratch);
        self.scratch.clear();
        self.scratch.extend(
            self.ratio
                .iter()
                .map(|r| mask((r * 1.0 + -1.0).abs() > config.clip_range)),
        );
        let clip_fraction = mean(&self.scratch);
        PolicyStats {
            policy_loss,
            entropy,
            approx_kl,
            clip_fraction,
        }
    }
}
