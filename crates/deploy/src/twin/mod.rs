//! A digital twin of the FAIRINO controller, backed by the simulator (being built: the
//! controller model, the world, faults, the pose feed and the call log so far).

pub mod call_log;
pub mod controller;
pub mod faults;
pub mod gripper;
pub mod motion;
pub mod pose_feed;
pub mod world;

#[cfg(test)]
mod controller_tests;
