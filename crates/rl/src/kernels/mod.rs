//! The networks' hot paths written out by hand. The first four compute exactly what candle's
//! ops computed (the same f32 operations in the same order, so trained weights are
//! bit-identical to candle's, tested in each module); the image layers, which no candle-trained
//! network preceded, are checked against candle's results to rounding:
//! - [`tanh`]: a vectorised tanh (candle's called libm once per value);
//! - [`candle_ops`]: a linear layer's bias add, ReLU and in-place Polyak averaging as single
//!   candle ops, for the networks that still run through candle's autograd (SAC, TD3);
//! - [`mlp`]: an MLP's forward and backward passes on plain slices (PPO's networks, and its
//!   loss written out in [`crate::ppo::fused_loss`]);
//! - [`conv`] and [`dense`]: convolutions (im2col), linear layers and ReLU, forward and
//!   backward, for the pixel policies' image encoders;
//! - [`product`]: the image layers' matrix products (an AVX2 kernel of our own where the CPU
//!   lacks AVX-512);
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
