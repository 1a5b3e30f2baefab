//! The networks' hot paths written out by hand. [`tanh`] and [`candle_ops`] compute exactly
//! what candle's ops computed (the same f32 operations in the same order, tested in each
//! module); [`mlp`] does too except for its matrix products, which sum in an order of their own
//! that every host repeats; the image layers, which no candle-trained network preceded, are
//! checked against candle's results to rounding:
//! - [`tanh`]: a vectorised tanh (candle's called libm once per value);
//! - [`candle_ops`]: a linear layer's bias add, ReLU and in-place Polyak averaging as single
//!   candle ops, for the networks that still run through candle's autograd (SAC, TD3);
//! - [`mlp`]: an MLP's forward and backward passes on plain slices (PPO's networks, and its
//!   loss written out in [`crate::ppo::fused_loss`]);
//! - [`conv`] and [`dense`]: convolutions (im2col), linear layers and ReLU, forward and
//!   backward, for the pixel policies' image encoders;
//! - [`product`]: the matrix products of the MLPs (an AVX2 kernel of our own on every CPU
//!   with AVX2 and FMA) and of the image layers (that kernel where the CPU lacks AVX-512);
//! - [`storage`]: a tensor's values read in place.
//!
//! Why by hand: at these networks' sizes candle's per-op allocation and bookkeeping cost more
//! than the arithmetic (each module says by how much).

pub mod candle_ops;
pub mod conv;
pub mod dense;
pub mod mlp;
pub mod product;
pub mod storage;
pub mod tanh;

/// `found` equals `want` to f32 rounding (sums in another order), what differs named: the
/// written-out passes against candle's in the tests.
#[cfg(test)]
pub(crate) fn assert_close(found: &[f32], want: &[f32], what: &str) {
    assert_eq!(found.len(), want.len(), "{what}");
    for (i, (a, b)) in found.iter().zip(want).enumerate() {
        assert!(
            (a - b).abs() <= 1e-5 * (1.0 + b.abs()),
            "{what}[{i}]: {a} against {b}"
        );
    }
}
