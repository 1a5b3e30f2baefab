//! The grasp task as a Gymnasium-style environment (observation, action, reward, reset/step).
//!
//! Layer 2 of fairgrasp: it depends only on [`fairgrasp_sim`]. The environment itself is built in
//! the "grasp task as a Gymnasium-style environment" issue; this crate holds its place in the layout.

pub use fairgrasp_sim as sim;
