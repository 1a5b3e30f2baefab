//! Networks and the optimiser, on candle: [`mlp`] (the perceptron and its initial weights),
//! [`adam`] (the optimiser, its state saved in checkpoints) and [`schedule`] (its step size
//! over training).

pub mod adam;
pub mod mlp;
pub mod schedule;

pub use adam::Adam;
pub use mlp::{Activation, Mlp};
pub use schedule::LrSchedule;
