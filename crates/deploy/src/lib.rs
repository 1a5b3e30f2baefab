//! Sim to real: policy export, calibration, the safety layer, the FAIRINO controller protocol
//! and a digital twin of the controller backed by the simulator.
//!
//! Layer 4 of fairgrasp. The pieces, by folder:
//! - [`robot`]: what any controller link offers the deployment loop (state in, commands out).
//! - [`fairino`]: the FAIRINO controller's protocol (XML-RPC on 20003, the CNDE state stream
//!   on 20005), client and server sides.
//! - [`twin`]: a controller made of the simulator, serving that protocol on loopback.
//! - [`safety`]: the layer between every policy output and the wire.
//! - [`calibration`]: simulator joints ↔ robot joints.
//! - [`pose_source`]: where the object's pose comes from on the real arm.
//! - [`export`]: ONNX and safetensors files of a trained policy.
//! - [`robustness`]: a policy's success over a grid of held-out conditions.

#![warn(missing_docs)]

pub mod calibration;
pub mod commissioning;
pub mod error;
pub mod export;
pub mod fairino;
pub mod frame_source;
pub mod kinematics;
pub mod pose_source;
pub mod robot;
pub mod robustness;
pub mod runner;
pub mod safety;
pub mod sysid;
pub mod twin;

pub use robot::{RobotCommand, RobotLink, RobotState, StampedState};

pub use error::{DeployError, Result};
pub use fairgrasp_sim as sim;
