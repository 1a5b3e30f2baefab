//! How joints are driven: the joint-space set-point ramp shared by the kinematic arm drive, the
//! environment's servo model and the deployment's safety filter, and the gripper's set point
//! and the drives' tracking, each shared by the twin's controller model and training.

mod drives;
mod gripper;
mod ramp;

pub use drives::{DriveFilter, DriveIntegral, JointTracking};
pub use gripper::{FINGERS_FULL_SPEED_PERCENT_PER_S, GripperRamp};
pub use ramp::JointRamp;
