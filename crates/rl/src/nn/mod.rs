//! Networks and the optimiser, on candle: [`mlp`] (the perceptron and its initial weights) and
//! [`adam`] (the optimiser, its state saved in checkpoints).

pub mod adam;
pub mod mlp;

pub use adam::Adam;
pub use mlp::{Activation, Mlp};
