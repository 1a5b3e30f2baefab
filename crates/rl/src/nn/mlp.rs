//! The multi-layer perceptron every network is built from, with its initial weights.

use candle_core::Tensor;
use candle_nn::{Init, Linear, VarBuilder, VarMap};
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Hidden-layer activation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Activation {
    /// Hyperbolic tangent (PPO's default).
    Tanh,
    /// `max(0, x)` (SAC's and TD3's default).
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

    /// `x` (`batch × input`) through every layer, the activation after each but the last:
    /// `batch × output`.
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
