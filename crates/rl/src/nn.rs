//! Networks and the optimiser, on candle.
//!
//! Adam is written here (a dozen tensor operations) rather than taken from candle-nn because
//! candle-nn's `AdamW` keeps its moment estimates private, and a resumable checkpoint must save
//! them.

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{Init, Linear, VarBuilder, VarMap};
use rand::Rng;
use serde::{Deserialize, Serialize};
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

/// A draw from N(0, 1) (Box–Muller).
pub fn standard_normal(rng: &mut impl Rng) -> f32 {
    let u1: f32 = rng.random::<f32>().max(1e-12);
    let u2: f32 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f32::consts::PI * u2).cos()
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
                .map(|_| *std as f32 * standard_normal(rng))
                .collect();
            var.set(&Tensor::from_vec(values, (fan_out, fan_in), var.device())?)?;
        }
        Ok(())
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
                x = crate::fused::add_bias(&x, b)?;
            }
            if i < last {
                x = match self.activation {
                    Activation::Tanh => crate::fast_tanh::tanh_tensor(&x)?,
                    Activation::Relu => crate::fused::relu(&x)?,
                };
            }
        }
        Ok(x)
    }
}

/// Adam (Kingma & Ba 2015) over the variables of a [`VarMap`], with its state exposed for
/// checkpoints.
///
/// The moments are plain vectors and each variable is updated in place in one pass
/// ([`AdamUpdate`]): the dozen candle ops per variable this replaced allocated a tensor each and
/// took a fifth of a SAC gradient step. The pass computes exactly what those ops did (same f32
/// operations in the same order), so results are unchanged bit for bit.
pub struct Adam {
    /// Variables by name, sorted so the order is stable.
    vars: Vec<(String, Var)>,
    first: Vec<Vec<f32>>,
    second: Vec<Vec<f32>>,
    pub lr: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
    step: u64,
}

/// One variable's Adam step, applied in place to its storage.
struct AdamUpdate<'a> {
    grad: &'a [f32],
    m: std::cell::RefCell<&'a mut [f32]>,
    v: std::cell::RefCell<&'a mut [f32]>,
    /// Multipliers as candle's scalar ops applied them (f64 rounded to f32).
    scale: Option<f32>,
    beta1: f32,
    one_minus_beta1: f32,
    beta2: f32,
    one_minus_beta2: f32,
    inv_bias1: f32,
    inv_bias2: f32,
    eps: f32,
    lr: f32,
}

impl candle_core::InplaceOp1 for AdamUpdate<'_> {
    fn name(&self) -> &'static str {
        "adam-update"
    }

    fn cpu_fwd(
        &self,
        storage: &mut candle_core::CpuStorage,
        layout: &candle_core::Layout,
    ) -> candle_core::Result<()> {
        let candle_core::CpuStorage::F32(data) = storage else {
            candle_core::bail!("Adam updates f32 variables only");
        };
        let Some((start, end)) = layout.contiguous_offsets() else {
            candle_core::bail!("Adam needs contiguous variables");
        };
        let (mut m, mut v) = (self.m.borrow_mut(), self.v.borrow_mut());
        let w = &mut data[start..end];
        if [self.grad.len(), m.len(), v.len()] != [w.len(); 3] {
            candle_core::bail!("Adam: gradient or moments do not match the variable");
        }
        // Zipped slices (no bounds checks), so the loop vectorises. `x * c + 0.0` is candle's
        // affine op (it turns −0 into +0, so it is kept).
        let moments = m.iter_mut().zip(v.iter_mut());
        for ((w, &g), (m, v)) in w.iter_mut().zip(self.grad).zip(moments) {
            let g = match self.scale {
                Some(s) => g * s + 0.0,
                None => g,
            };
            let mi = (*m * self.beta1 + 0.0) + (g * self.one_minus_beta1 + 0.0);
            let vi = (*v * self.beta2 + 0.0) + ((g * g) * self.one_minus_beta2 + 0.0);
            let denom = (vi * self.inv_bias2 + 0.0).sqrt() + self.eps;
            let update = (mi * self.inv_bias1 + 0.0) / denom;
            *w -= update * self.lr + 0.0;
            *m = mi;
            *v = vi;
        }
        Ok(())
    }
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
        let zeros = |v: &Var| vec![0.0f32; v.as_tensor().elem_count()];
        Ok(Self {
            first: vars.iter().map(|(_, v)| zeros(v)).collect(),
            second: vars.iter().map(|(_, v)| zeros(v)).collect(),
            vars,
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            step: 0,
        })
    }

    /// One step on `loss`, with the global gradient norm clipped to `max_grad_norm` (0: no
    /// clipping, and the norm is not computed). Returns the gradient norm before clipping.
    pub fn backward_step(&mut self, loss: &Tensor, max_grad_norm: f64) -> candle_core::Result<f64> {
        let grads = loss.backward()?;
        let mut grad_list = Vec::with_capacity(self.vars.len());
        let mut sq = 0.0f64;
        for (_, var) in &self.vars {
            let g = grads.get(var).cloned();
            if max_grad_norm > 0.0
                && let Some(g) = &g
            {
                sq += g.sqr()?.sum_all()?.to_scalar::<f32>()? as f64;
            }
            grad_list.push(g);
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
        for (i, g) in grad_list.into_iter().enumerate() {
            let Some(g) = g else { continue };
            let (first, second) = (&mut self.first[i], &mut self.second[i]);
            with_f32_slice(&g, |grad| {
                let op = AdamUpdate {
                    grad,
                    m: std::cell::RefCell::new(first),
                    v: std::cell::RefCell::new(second),
                    scale,
                    beta1: self.beta1 as f32,
                    one_minus_beta1: (1.0 - self.beta1) as f32,
                    beta2: self.beta2 as f32,
                    one_minus_beta2: (1.0 - self.beta2) as f32,
                    inv_bias1: (1.0 / bias1) as f32,
                    inv_bias2: (1.0 / bias2) as f32,
                    eps: self.eps as f32,
                    lr: self.lr as f32,
                };
                self.vars[i].1.as_tensor().inplace_op1(&op)
            })??;
        }
        Ok(norm)
    }

    /// The optimiser state as named tensors (for a checkpoint).
    pub fn state(&self) -> candle_core::Result<HashMap<String, Tensor>> {
        let mut out = HashMap::new();
        for (i, (name, _)) in self.vars.iter().enumerate() {
            let shape = self.vars[i].1.shape();
            for (kind, values) in [("m", &self.first[i]), ("v", &self.second[i])] {
                let t = Tensor::from_slice(values, shape, &Device::Cpu)?;
                out.insert(format!("adam.{kind}.{name}"), t);
            }
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
                    .and_then(|t| t.flatten_all()?.to_vec1::<f32>())
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
