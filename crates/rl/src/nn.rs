//! Networks and the optimiser, on candle.
//!
//! Adam is written here (a dozen tensor operations) rather than taken from candle-nn because
//! candle-nn's `AdamW` keeps its moment estimates private, and a resumable checkpoint must save
//! them.

use candle_core::cpu::kernels::VecOps;
use candle_core::{CpuStorage, DType, Device, InplaceOp1, Layout, Tensor, Var};
use candle_nn::{Init, Linear, VarBuilder, VarMap};
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::cell::Cell;
use std::collections::HashMap;

/// Hidden-layer activation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Activation {
    Tanh,
    Relu,
}

/// A multi-layer perceptron.
#[derive(Clone, Debug)]
pub struct Mlp {
    layers: Vec<Linear>,
    activation: Activation,
    /// Full name and initial standard deviation of each layer's weight matrix.
    weight_init: Vec<(String, f64)>,
}

/// A linear layer with zero weights and bias; [`Mlp::init_weights`] draws the weights.
fn linear(
    vb: &VarBuilder,
    name: &str,
    fan_in: usize,
    fan_out: usize,
) -> candle_core::Result<Linear> {
    let weight = vb.get_with_hints(
        (fan_out, fan_in),
        &format!("{name}.weight"),
        Init::Const(0.0),
    )?;
    let bias = vb.get_with_hints(fan_out, &format!("{name}.bias"), Init::Const(0.0))?;
    Ok(Linear::new(weight, Some(bias)))
}

impl Mlp {
    /// `input → hidden… → output`, weights zero until [`Self::init_weights`]. Hidden layers are
    /// initialised with gain √2, the output layer with `output_gain` (small for policy means, so
    /// the first actions are near zero, as CleanRL does).
    pub fn new(
        vb: &VarBuilder,
        input: usize,
        hidden: &[usize],
        output: usize,
        activation: Activation,
        output_gain: f64,
    ) -> candle_core::Result<Self> {
        let mut layers = Vec::new();
        let mut weight_init = Vec::new();
        let mut fan_in = input;
        let sizes = hidden.iter().copied().chain([output]);
        for (i, fan_out) in sizes.enumerate() {
            let name = format!("l{i}");
            layers.push(linear(vb, &name, fan_in, fan_out)?);
            let gain = if i == hidden.len() {
                output_gain
            } else {
                std::f64::consts::SQRT_2
            };
            let prefix = vb.prefix();
            let full = if prefix.is_empty() {
                format!("{name}.weight")
            } else {
                format!("{prefix}.{name}.weight")
            };
            weight_init.push((full, gain / (fan_in as f64).sqrt()));
            fan_in = fan_out;
        }
        Ok(Self {
            layers,
            activation,
            weight_init,
        })
    }

    /// Draws the weights from N(0, (gain / √fan_in)²) with `rng`, layer by layer, so a seed
    /// fixes the network. (candle's own initialisers draw from an unseeded thread-local
    /// generator.) `varmap` is the map the network was built in.
    pub fn init_weights(&self, varmap: &VarMap, rng: &mut impl Rng) -> candle_core::Result<()> {
        let data = varmap.data().lock().expect("varmap lock");
        for (name, std) in &self.weight_init {
            let var = data
                .get(name)
                .ok_or_else(|| candle_core::Error::Msg(format!("no variable `{name}`")))?;
            let (fan_out, fan_in) = var.as_tensor().dims2()?;
            let values: Vec<f32> = (0..fan_out * fan_in)
                .map(|_| *std as f32 * fairgrasp_env::random::standard_normal(rng))
                .collect();
            var.set(&Tensor::from_vec(values, (fan_out, fan_in), var.device())?)?;
        }
        Ok(())
    }

    /// Each layer's weight (`out × in`) and bias, input layer first.
    pub fn layer_tensors(&self) -> Vec<(&Tensor, &Tensor)> {
        self.layers
            .iter()
            .map(|l| (l.weight(), l.bias().expect("Mlp layers have biases")))
            .collect()
    }

    pub fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        self.forward_with(x, false)
    }

    /// The forward pass with the weights as constants: gradients reach the input but no
    /// weight's gradient is computed. SAC's actor loss goes through the critics this way; their
    /// weight gradients were a tenth of a gradient step, and only the actor's optimiser steps.
    pub fn forward_detached(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        self.forward_with(x, true)
    }

    fn forward_with(&self, x: &Tensor, detached: bool) -> candle_core::Result<Tensor> {
        let mut x = x.clone();
        let last = self.layers.len() - 1;
        for (i, layer) in self.layers.iter().enumerate() {
            let (mut w, mut b) = (layer.weight().clone(), layer.bias().cloned());
            if detached {
                w = w.detach();
                b = b.map(|b| b.detach());
            }
            // What candle-nn's `Linear` computes, with the bias added by one op.
            x = x.matmul(&w.t()?)?;
            if let Some(b) = &b {
                x = crate::kernels::candle_ops::add_bias(&x, b)?;
            }
            if i < last {
                x = match self.activation {
                    Activation::Tanh => crate::kernels::tanh::tanh_tensor(&x)?,
                    Activation::Relu => crate::kernels::candle_ops::relu(&x)?,
                };
            }
        }
        Ok(x)
    }
}

/// Adam (Kingma & Ba 2015) over the variables of a [`VarMap`], with its state exposed for
/// checkpoints.
///
/// The step runs as plain loops over each parameter's values, updating the variable in place.
/// As candle tensor operations it was ~16 operations (each allocating its result) per parameter
/// tensor, 200 per PPO minibatch: with PPO's loss written out ([`crate::kernels::ppo_loss`]) that was
/// 0.55 ms per design-setting minibatch step, 0.41–0.46 ms with these loops. They do the same
/// f32 arithmetic in the same order (candle's `x · c` is `x · (c as f32) + 0`, its sums are
/// [`VecOps::vec_reduce_sum`]), so the weights are bit-identical to the tensor version's.
pub struct Adam {
    /// Variables by name, sorted so the order is stable.
    vars: Vec<(String, Var)>,
    /// First and second moment estimates, row-major like their variables.
    first: Vec<Vec<f32>>,
    second: Vec<Vec<f32>>,
    pub lr: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
    step: u64,
    /// Squared gradient values, for the norm.
    scratch: Vec<f32>,
}

/// The values of a contiguous f32 tensor, read in place.
pub(crate) fn with_f32_slice<R>(t: &Tensor, f: impl FnOnce(&[f32]) -> R) -> candle_core::Result<R> {
    let t = t.contiguous()?;
    let (storage, layout) = t.storage_and_layout();
    let candle_core::Storage::Cpu(cpu) = &*storage else {
        candle_core::bail!("f32 CPU tensors only");
    };
    let data = cpu.as_slice::<f32>()?;
    let (start, end) = layout
        .contiguous_offsets()
        .ok_or_else(|| candle_core::Error::Msg("non-contiguous tensor".into()))?;
    Ok(f(&data[start..end]))
}

impl Adam {
    pub fn new(varmap: &VarMap, lr: f64) -> candle_core::Result<Self> {
        let mut vars: Vec<(String, Var)> = varmap
            .data()
            .lock()
            .expect("varmap lock")
            .iter()
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        vars.sort_by(|a, b| a.0.cmp(&b.0));
        let zeros: Vec<Vec<f32>> = vars
            .iter()
            .map(|(_, v)| vec![0.0; v.elem_count()])
            .collect();
        Ok(Self {
            first: zeros.clone(),
            second: zeros,
            vars,
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            step: 0,
            scratch: Vec::new(),
        })
    }

    /// The variables in the order [`Self::step_with`] takes their gradients (sorted by name).
    pub fn vars(&self) -> impl Iterator<Item = (&str, &Var)> {
        self.vars.iter().map(|(name, var)| (name.as_str(), var))
    }

    /// One step on `loss`, with the global gradient norm clipped to `max_grad_norm`.
    /// Returns the gradient norm before clipping.
    pub fn backward_step(&mut self, loss: &Tensor, max_grad_norm: f64) -> candle_core::Result<f64> {
        let grads = loss.backward()?;
        let grad_list = self
            .vars
            .iter()
            .map(|(_, var)| {
                grads
                    .get(var)
                    .map(|g| g.flatten_all()?.to_vec1::<f32>())
                    .transpose()
            })
            .collect::<candle_core::Result<Vec<_>>>()?;
        let refs: Vec<Option<&[f32]>> = grad_list.iter().map(|g| g.as_deref()).collect();
        self.step_with(&refs, max_grad_norm)
    }

    /// One step with the gradients given, one per variable in [`Self::vars`] order, row-major
    /// (`None`: the variable gets no gradient and is left alone), the global norm clipped to
    /// `max_grad_norm`. Returns the gradient norm before clipping.
    pub fn step_with(
        &mut self,
        grads: &[Option<&[f32]>],
        max_grad_norm: f64,
    ) -> candle_core::Result<f64> {
        if grads.len() != self.vars.len() {
            candle_core::bail!(
                "{} gradients for {} variables",
                grads.len(),
                self.vars.len()
            );
        }
        let mut sq = 0.0f64;
        for g in grads.iter().flatten() {
            self.scratch.clear();
            self.scratch.extend(g.iter().map(|v| v * v));
            let mut sum = 0.0f32;
            // SAFETY: `scratch` holds `len` values and `sum` is one.
            unsafe { f32::vec_reduce_sum(self.scratch.as_ptr(), &mut sum, self.scratch.len()) };
            sq += sum as f64;
        }
        let norm = sq.sqrt();
        let scale = if max_grad_norm > 0.0 && norm > max_grad_norm {
            Some((max_grad_norm / (norm + 1e-6)) as f32)
        } else {
            None
        };
        self.step += 1;
        let t = self.step as i32;
        let bias1 = 1.0 - self.beta1.powi(t);
        let bias2 = 1.0 - self.beta2.powi(t);
        // candle's affine `x · mul + add` with its f64 constants cast to f32.
        let (b1, c1) = (self.beta1 as f32, (1.0 - self.beta1) as f32);
        let (b2, c2) = (self.beta2 as f32, (1.0 - self.beta2) as f32);
        let (inv_bias1, inv_bias2) = ((1.0 / bias1) as f32, (1.0 / bias2) as f32);
        let (eps, lr) = (self.eps as f32, self.lr as f32);
        for (i, g) in grads.iter().enumerate() {
            let Some(g) = g else { continue };
            let (m, v) = (&mut self.first[i], &mut self.second[i]);
            if g.len() != m.len() {
                candle_core::bail!(
                    "gradient of {} values for `{}` of {}",
                    g.len(),
                    self.vars[i].0,
                    m.len()
                );
            }
            let update = AdamUpdate {
                grad: g,
                first: Cell::from_mut(m.as_mut_slice()).as_slice_of_cells(),
                second: Cell::from_mut(v.as_mut_slice()).as_slice_of_cells(),
                scale,
                consts: [b1, c1, b2, c2, inv_bias1, inv_bias2, eps, lr],
            };
            self.vars[i].1.as_tensor().inplace_op1(&update)?;
        }
        Ok(norm)
    }

    /// The optimiser state as named tensors (for a checkpoint).
    pub fn state(&self) -> candle_core::Result<HashMap<String, Tensor>> {
        let mut out = HashMap::new();
        for (i, (name, var)) in self.vars.iter().enumerate() {
            let shape = var.shape();
            let tensor = |v: &Vec<f32>| Tensor::from_slice(v, shape, &Device::Cpu);
            out.insert(format!("adam.m.{name}"), tensor(&self.first[i])?);
            out.insert(format!("adam.v.{name}"), tensor(&self.second[i])?);
        }
        out.insert(
            "adam.step".into(),
            Tensor::new(&[self.step as f64], &Device::Cpu)?,
        );
        Ok(out)
    }

    /// Restores a state saved by [`Self::state`]; errors name a missing or mis-shaped tensor.
    pub fn load_state(&mut self, state: &HashMap<String, Tensor>) -> Result<(), String> {
        for (i, (name, var)) in self.vars.iter().enumerate() {
            for (kind, slot) in [("m", &mut self.first[i]), ("v", &mut self.second[i])] {
                let key = format!("adam.{kind}.{name}");
                let t = state
                    .get(&key)
                    .ok_or_else(|| format!("optimiser state lacks `{key}`"))?;
                if t.dims() != var.dims() {
                    return Err(format!(
                        "`{key}` has shape {:?}, the parameter {:?}",
                        t.dims(),
                        var.dims()
                    ));
                }
                *slot = t
                    .to_dtype(DType::F32)
                    .and_then(|t| t.flatten_all()?.to_vec1())
                    .map_err(|e| e.to_string())?;
            }
        }
        let step = state
            .get("adam.step")
            .ok_or("optimiser state lacks `adam.step`")?
            .to_vec1::<f64>()
            .map_err(|e| e.to_string())?;
        self.step = step.first().copied().unwrap_or(0.0) as u64;
        Ok(())
    }
}

/// One parameter's Adam update, applied in place to the variable's storage.
struct AdamUpdate<'a> {
    grad: &'a [f32],
    first: &'a [Cell<f32>],
    second: &'a [Cell<f32>],
    /// The gradient-clipping factor, when clipping.
    scale: Option<f32>,
    /// β1, 1 − β1, β2, 1 − β2, 1 / (1 − β1ᵗ), 1 / (1 − β2ᵗ), ε, learning rate.
    consts: [f32; 8],
}

impl InplaceOp1 for AdamUpdate<'_> {
    fn name(&self) -> &'static str {
        "adam-update"
    }

    fn cpu_fwd(&self, storage: &mut CpuStorage, layout: &Layout) -> candle_core::Result<()> {
        let (CpuStorage::F32(values), Some((start, end))) = (storage, layout.contiguous_offsets())
        else {
            candle_core::bail!("Adam updates contiguous f32 variables");
        };
        let [b1, c1, b2, c2, inv_bias1, inv_bias2, eps, lr] = self.consts;
        let moments = self.first.iter().zip(self.second);
        for ((w, &g), (m, v)) in values[start..end].iter_mut().zip(self.grad).zip(moments) {
            let g = match self.scale {
                Some(s) => g * s + 0.0,
                None => g,
            };
            m.set((m.get() * b1 + 0.0) + (g * c1 + 0.0));
            v.set((v.get() * b2 + 0.0) + (g * g * c2 + 0.0));
            let update = (m.get() * inv_bias1 + 0.0) / ((v.get() * inv_bias2 + 0.0).sqrt() + eps);
            *w -= update * lr + 0.0;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adam_fits_a_linear_function_and_its_state_round_trips() {
        let dev = Device::Cpu;
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, &dev);
        let net = Mlp::new(&vb, 2, &[16], 1, Activation::Tanh, 1.0).unwrap();
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0);
        net.init_weights(&varmap, &mut rng).unwrap();
        let mut adam = Adam::new(&varmap, 1e-2).unwrap();
        let x = Tensor::new(&[[0.1f32, 0.2], [0.5, -0.3], [-0.4, 0.8], [0.9, 0.1]], &dev).unwrap();
        let y = Tensor::new(&[[0.5f32], [-0.1], [1.2], [1.1]], &dev).unwrap(); // y = x0 + 2 x1 + 0.0.
        let loss = |net: &Mlp| {
            (net.forward(&x).unwrap() - &y)
                .unwrap()
                .sqr()
                .unwrap()
                .mean_all()
                .unwrap()
        };
        let first = loss(&net).to_scalar::<f32>().unwrap();
        for _ in 0..300 {
            adam.backward_step(&loss(&net), 10.0).unwrap();
        }
        let last = loss(&net).to_scalar::<f32>().unwrap();
        assert!(last < first * 0.05, "loss {first} -> {last}");
        let state = adam.state().unwrap();
        let mut other = Adam::new(&varmap, 1e-2).unwrap();
        other.load_state(&state).unwrap();
        assert_eq!(other.step, 300);
        let mut broken = state.clone();
        broken.remove("adam.step");
        assert!(other.load_state(&broken).unwrap_err().contains("adam.step"));
    }
}
