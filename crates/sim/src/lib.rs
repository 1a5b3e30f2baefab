//! fairgrasp-sim: a simulated FAIRINO arm with a parallel gripper, a table and objects.
//!
//! Layer 1 of fairgrasp (sim → render → env → rl → deploy). Built on rapier3d multibodies:
//! - [`model`]: URDF loading and validation (meshes, `package://` paths, clear errors);
//! - [`robot`]: the model as a multibody with PD/torque control and state queries;
//! - [`kinematics`]: forward and inverse kinematics of a chain;
//! - [`envelope`]: spheres covering the arm's shapes, for clearance checks;
//! - [`scene`]: the grasp scene (arm, gripper, table, objects, bins), stepping, reset and queries;
//! - [`pick`]: a scripted pick-and-lift controller and the task's success rule;
//! - [`assets`]: the bundled FR5 and gripper descriptions.

#![warn(missing_docs)]

pub mod assets;
pub mod control;
pub mod envelope;
pub mod error;
pub mod kinematics;
pub mod math;
pub mod model;
pub mod pick;
pub mod robot;
pub mod scene;

pub use error::{Result, SimError};
pub use rapier3d;
