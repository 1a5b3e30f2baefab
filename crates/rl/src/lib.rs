//! Reinforcement learning (PPO, SAC) on top of the grasp environment.
//!
//! Layer 3 of fairgrasp: it will depend on the environment crate. Built in the training issue; this
//! crate holds its place in the layout.

pub use fairgrasp_sim as sim;
