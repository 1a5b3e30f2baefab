//! How joints are driven: the joint-space set-point ramp shared by the kinematic arm drive, the
//! environment's servo model and the deployment's safety filter.

mod ramp;

pub use ramp::JointRamp;
