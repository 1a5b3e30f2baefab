//! Sim-to-real: policy export, calibration, the safety layer and the FAIRINO controller protocol.
//!
//! Layer 4 of fairgrasp. Built in the sim-to-real issues; this crate holds its place in the layout.

pub use fairgrasp_sim as sim;
