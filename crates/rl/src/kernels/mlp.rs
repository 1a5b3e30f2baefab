//! [`crate::nn::Mlp`]'s forward and backward passes (tanh hidden layers) written out on plain
//! f32 slices, for PPO's small networks.
//!
//! Why: with the design's settings ([64, 64] networks, minibatches of 256) a PPO gradient step
//! through candle's autograd ran a few hundred tensor operations, each allocating its result
//! and costing microseconds whatever its size: ~1 ms of CPU per minibatch step, of which the
//! arithmetic is a small part. Here the same arithmetic runs on reused buffers (0.3 ms, with
//! [`crate::ppo::fused_loss`]).
//!
//! The matrix products (`x · Wᵀ`, and `g · W`, `xᵀ · g` in the backward pass) run on our AVX2
//! kernel ([`ProductKernel::Avx2`]) on every CPU with AVX2 and FMA, whose sums run in one order
//! on all of them, so a seed trains the same PPO weights on an AVX-512 host and an AVX2-only
//! one (gemm's kernels, which candle's `Linear` calls, sum in each CPU's own order). Everything
//! else is candle's arithmetic: the bias gradients sum rows in candle's order, and the
//! elementwise steps are its formulas (tanh through [`crate::kernels::tanh::tanh`], its slope
//! `1 − y²` as `y² · (−1) + 1`); so the results are candle's to rounding.

use crate::kernels::product::{ProductKernel, product_with};
use crate::kernels::tanh;
use crate::nn::Mlp;
use candle_core::cpu::kernels::VecOps;
use candle_core::{CpuStorage, Layout, Storage, Tensor};

/// candle's sum of a contiguous run of values (its order: SIMD lanes, then the tail).
pub fn sum(values: &[f32]) -> f32 {
    let mut out = 0.0f32;
    // SAFETY: `values` holds `len` values; `out` is one.
    unsafe { f32::vec_reduce_sum(values.as_ptr(), &mut out, values.len()) };
    out
}

/// The values of f32 CPU tensors (the networks' variables), borrowed (read-locked) for one pass.
pub struct VarValues<'a> {
    guards: Vec<(candle_core::StorageRef<'a>, &'a Layout)>,
}

impl<'a> VarValues<'a> {
    /// Read-locks each of `tensors` until dropped.
    pub fn new(tensors: impl IntoIterator<Item = &'a Tensor>) -> Self {
        Self {
            guards: tensors
                .into_iter()
                .map(|t| t.storage_and_layout())
                .collect(),
        }
    }

    /// The values of the `i`-th tensor, row-major.
    pub fn get(&self, i: usize) -> candle_core::Result<&[f32]> {
        let (storage, layout) = &self.guards[i];
        match (&**storage, layout.contiguous_offsets()) {
            (Storage::Cpu(CpuStorage::F32(v)), Some((start, end))) => Ok(&v[start..end]),
            _ => candle_core::bail!("the fused MLP takes contiguous f32 CPU variables"),
        }
    }
}

/// One linear layer's parameters: `weight` is `out × inp` row-major.
#[derive(Clone, Copy)]
pub struct LayerParams<'a> {
    /// `out × inp`, row-major.
    pub weight: &'a [f32],
    /// `out` values.
    pub bias: &'a [f32],
    /// Input width.
    pub inp: usize,
    /// Output width.
    pub out: usize,
}

/// The layers whose weights and biases are `tensors` (as [`Mlp::layer_tensors`] lists them),
/// with their values at `values.get(offset + 2l)` and `values.get(offset + 2l + 1)`.
pub fn layers_from<'v>(
    values: &'v VarValues<'_>,
    tensors: &[(&Tensor, &Tensor)],
    offset: usize,
) -> candle_core::Result<Vec<LayerParams<'v>>> {
    tensors
        .iter()
        .enumerate()
        .map(|(l, (w, _))| {
            let (out, inp) = w.dims2()?;
            Ok(LayerParams {
                weight: values.get(offset + 2 * l)?,
                bias: values.get(offset + 2 * l + 1)?,
                inp,
                out,
            })
        })
        .collect()
}

/// [`forward`] through `mlp` over `batch` rows of `x`: its output, `batch × out`.
pub fn forward_mlp(mlp: &Mlp, x: &[f32], batch: usize) -> candle_core::Result<Vec<f32>> {
    let tensors = mlp.layer_tensors();
    let values = VarValues::new(tensors.iter().flat_map(|(w, b)| [*w, *b]));
    let layers = layers_from(&values, &tensors, 0)?;
    let mut buffers = MlpBuffers::default();
    forward(&layers, x, batch, &mut buffers);
    Ok(buffers.outputs.pop().unwrap_or_default())
}

/// Reusable buffers of one MLP's passes over a batch: each layer's output (after tanh for hidden
/// layers) and the gradient buffers. They are resized, not cleared, between passes: every value
/// is overwritten (the zeroing was 2 % of a PPO update).
#[derive(Default)]
pub struct MlpBuffers {
    /// `outputs[l]`: layer `l`'s output, `batch × out_l`.
    pub outputs: Vec<Vec<f32>>,
    grad: Vec<f32>,
    grad_in: Vec<f32>,
    weight_t: Vec<f32>,
}

/// The forward pass of `layers` (tanh between them, none after the last) over `batch` rows of
/// `x`; the output is `buffers.outputs.last()`.
pub fn forward(layers: &[LayerParams<'_>], x: &[f32], batch: usize, buffers: &mut MlpBuffers) {
    buffers.outputs.resize_with(layers.len(), Vec::new);
    let last = layers.len() - 1;
    for (l, p) in layers.iter().enumerate() {
        let (done, rest) = buffers.outputs.split_at_mut(l);
        let input = if l == 0 { x } else { &done[l - 1] };
        let out = &mut rest[0];
        // Every value is overwritten below (the product does not read its destination).
        out.resize(batch * p.out, 0.0);
        // x · Wᵀ: Wᵀ is W's transposed view, row stride 1 and column stride `inp`.
        product_with(
            ProductKernel::Avx2,
            (batch, p.out, p.inp),
            out,
            input,
            (p.inp, 1),
            p.weight,
            (1, p.inp),
        );
        for row in out.chunks_exact_mut(p.out) {
            for (v, b) in row.iter_mut().zip(p.bias) {
                *v += b;
            }
        }
        if l < last {
            tanh::tanh_in_place(out);
        }
    }
}

/// The backward pass after [`forward`] on the same `x`: from `grad_out` (`batch × out` of the
/// last layer) to each layer's weight and bias gradients, written into `grads[l] = (weight,
/// bias)` (row-major like the parameters).
pub fn backward(
    layers: &[LayerParams<'_>],
    x: &[f32],
    batch: usize,
    grad_out: &[f32],
    buffers: &mut MlpBuffers,
    grads: &mut [(Vec<f32>, Vec<f32>)],
) {
    let MlpBuffers {
        outputs,
        grad,
        grad_in,
        weight_t,
    } = buffers;
    grad.clear();
    grad.extend_from_slice(grad_out);
    for l in (0..layers.len()).rev() {
        let p = layers[l];
        let input = if l == 0 { x } else { &outputs[l - 1] };
        let (gw, gb) = &mut grads[l];
        // Bias: the broadcast's gradient, summed over rows in order.
        gb.clear();
        gb.resize(p.out, 0.0);
        for row in grad.chunks_exact(p.out) {
            for (acc, g) in gb.iter_mut().zip(row) {
                *acc += g;
            }
        }
        // Wᵀ's gradient xᵀ · g (`inp × out`), then transposed into W's layout.
        weight_t.resize(p.inp * p.out, 0.0);
        product_with(
            ProductKernel::Avx2,
            (p.inp, p.out, batch),
            weight_t,
            input,
            (1, p.inp),
            grad,
            (p.out, 1),
        );
        gw.resize(p.out * p.inp, 0.0);
        for (i, row) in weight_t.chunks_exact(p.out).enumerate() {
            for (o, &v) in row.iter().enumerate() {
                gw[o * p.inp + i] = v;
            }
        }
        if l == 0 {
            break;
        }
        // The input's gradient g · W, through the previous layer's tanh: slope y² · (−1) + 1.
        grad_in.resize(batch * p.inp, 0.0);
        product_with(
            ProductKernel::Avx2,
            (batch, p.inp, p.out),
            grad_in,
            grad,
            (p.out, 1),
            p.weight,
            (p.inp, 1),
        );
        for (g, &y) in grad_in.iter_mut().zip(input) {
            *g *= -(y * y) + 1.0;
        }
        std::mem::swap(grad, grad_in);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::assert_close;
    use crate::nn::Activation;
    use candle_core::{DType, Device, Var};
    use candle_nn::{VarBuilder, VarMap};
    use rand::SeedableRng;

    #[test]
    fn forward_and_backward_match_candle() {
        let (batch, inp, hidden, out) = (37, 11, 16, 3);
        let dev = Device::Cpu;
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, &dev);
        let net = Mlp::new(
            &vb.pp("n"),
            inp,
            &[hidden, hidden],
            out,
            Activation::Tanh,
            0.5,
        )
        .unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        net.init_weights(&varmap, &mut rng).unwrap();
        let x: Vec<f32> = (0..batch * inp)
            .map(|_| fairgrasp_env::random::standard_normal(&mut rng))
            .collect();
        let upstream: Vec<f32> = (0..batch * out)
            .map(|_| fairgrasp_env::random::standard_normal(&mut rng))
            .collect();
        let xt = Tensor::from_slice(&x, (batch, inp), &dev).unwrap();
        let y = net.forward(&xt).unwrap();
        let ut = Tensor::from_slice(&upstream, (batch, out), &dev).unwrap();
        let grads = (&y * &ut).unwrap().sum_all().unwrap().backward().unwrap();

        let data = varmap.data().lock().unwrap();
        let names: Vec<String> = (0..3)
            .flat_map(|l| [format!("n.l{l}.weight"), format!("n.l{l}.bias")])
            .collect();
        let vars: Vec<&Var> = names.iter().map(|n| &data[n]).collect();
        let values = VarValues::new(vars.iter().map(|v| v.as_tensor()));
        let dims = [(inp, hidden), (hidden, hidden), (hidden, out)];
        let layers: Vec<LayerParams> = dims
            .iter()
            .enumerate()
            .map(|(l, &(i, o))| LayerParams {
                weight: values.get(2 * l).unwrap(),
                bias: values.get(2 * l + 1).unwrap(),
                inp: i,
                out: o,
            })
            .collect();
        let mut buffers = MlpBuffers::default();
        forward(&layers, &x, batch, &mut buffers);
        let want: Vec<f32> = y.flatten_all().unwrap().to_vec1().unwrap();
        assert_close(&buffers.outputs[2], &want, "output");
        let mut ours = vec![(Vec::new(), Vec::new()); 3];
        backward(&layers, &x, batch, &upstream, &mut buffers, &mut ours);
        for (l, (gw, gb)) in ours.iter().enumerate() {
            let get = |v: &Var| -> Vec<f32> {
                grads
                    .get(v)
                    .unwrap()
                    .flatten_all()
                    .unwrap()
                    .to_vec1()
                    .unwrap()
            };
            assert_close(
                gw,
                &get(vars[2 * l]),
                &format!("weight gradient of layer {l}"),
            );
            assert_close(
                gb,
                &get(vars[2 * l + 1]),
                &format!("bias gradient of layer {l}"),
            );
        }
    }
}
