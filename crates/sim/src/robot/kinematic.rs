//! The kinematic arm drive (`arm.drive = "kinematic"`): joints that follow their targets
//! exactly as a position-controlled industrial arm does, instead of through torque-level PD
//! motors.
//!
//! The real FR5 is servoed by its controller (ServoJ): its joints track the commanded
//! trajectory within speed and acceleration limits whatever the payload. Here every arm joint
//! moves through a [`JointRamp`] each physics step, and the links are kinematic bodies placed
//! by forward kinematics, so rapier computes no articulated mass matrix for them (that work was
//! about 20–25 % of a PPO run's profile). The gripper's joints stay dynamic: its
//! fingers are dynamic bodies on impulse joints with PD motors, so they stop on an object and
//! squeeze it with the configured force.

use super::{JointGeometry, Robot};
use crate::control::JointRamp;
use crate::math::{iso_to_pose, pose_to_iso};
use crate::model::JointKind;
use rapier3d::na::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};
use rapier3d::prelude::*;

/// Per-joint realisation and drive state of the kinematic arm.
#[derive(Clone, Debug)]
pub(crate) struct KinematicArm {
    /// Per robot joint: its impulse joint when it stays dynamic, `None` when kinematic.
    pub(crate) impulse: Vec<Option<ImpulseJointHandle>>,
    /// Robot joint indices of the kinematic joints, in order (the ramp's joints).
    pub(crate) ramp_joints: Vec<usize>,
    pub(crate) ramp: JointRamp,
    /// Positions and velocities of the kinematic joints, per robot joint (zero for dynamic
    /// ones, which are read from their bodies).
    pub(crate) q: Vec<f32>,
    pub(crate) qd: Vec<f32>,
    /// The share of the gap to the ramp's set point a joint closes per physics step: 1 without
    /// a tracking lag, `1 − e^(−dt/lag)` with one.
    pub(crate) follow: f32,
}

impl KinematicArm {
    /// A drive for `joints` (per robot joint: `None` for kinematic): the ramp's caps in rad/s
    /// and rad/s² and the tracking lag in s (`motion`), `dt` the physics step.
    pub(crate) fn new(
        impulse: Vec<Option<ImpulseJointHandle>>,
        limits: &[(f32, f32)],
        motion: (f32, f32, f32),
        dt: f32,
    ) -> Self {
        let (speed, acc, lag) = motion;
        let ramp_joints: Vec<usize> = (0..impulse.len())
            .filter(|&j| impulse[j].is_none())
            .collect();
        let ramp_limits: Vec<(f64, f64)> = ramp_joints
            .iter()
            .map(|&j| (limits[j].0 as f64, limits[j].1 as f64))
            .collect();
        let n = impulse.len();
        Self {
            impulse,
            ramp: JointRamp::new(&ramp_limits, speed as f64, acc as f64, dt as f64),
            ramp_joints,
            q: vec![0.0; n],
            qd: vec![0.0; n],
            follow: if lag > 0.0 {
                1.0 - (-dt / lag).exp()
            } else {
                1.0
            },
        }
    }
}

/// The motion of a joint at position `q`, in its origin frame.
fn joint_motion(kind: JointKind, axis: &Unit<Vector3<f64>>, q: f64) -> Isometry3<f64> {
    match kind {
        JointKind::Prismatic => Isometry3::from_parts(
            Translation3::from(axis.into_inner() * q),
            UnitQuaternion::identity(),
        ),
        _ => Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(axis, q),
        ),
    }
}

/// World poses of every body for joint positions `q` (all joints), the root where it is.
pub(crate) fn body_poses(
    root: Isometry3<f64>,
    geometry: &[JointGeometry],
    n_bodies: usize,
    q: &[f32],
) -> Vec<Isometry3<f64>> {
    let mut poses = vec![root; n_bodies];
    for (g, &qj) in geometry.iter().zip(q) {
        poses[g.child_body] =
            poses[g.parent_body] * g.origin * joint_motion(g.kind, &g.axis, qj as f64);
    }
    poses
}

/// A dynamic joint's position, read from its two bodies.
pub(crate) fn measured_position(
    g: &JointGeometry,
    bodies: &RigidBodySet,
    handles: &[RigidBodyHandle],
) -> f32 {
    let parent = pose_to_iso(bodies[handles[g.parent_body]].position());
    let child = pose_to_iso(bodies[handles[g.child_body]].position());
    let relative = (parent * g.origin).inverse() * child;
    match g.kind {
        JointKind::Prismatic => relative.translation.vector.dot(&g.axis) as f32,
        _ => relative.rotation.scaled_axis().dot(&g.axis) as f32,
    }
}

/// A dynamic joint's velocity, read from its two bodies.
pub(crate) fn measured_velocity(
    g: &JointGeometry,
    bodies: &RigidBodySet,
    handles: &[RigidBodyHandle],
) -> f32 {
    let (parent, child) = (
        &bodies[handles[g.parent_body]],
        &bodies[handles[g.child_body]],
    );
    let frame = pose_to_iso(parent.position()) * g.origin;
    let axis = frame.rotation * g.axis.into_inner();
    let axis = Vector::new(axis.x as f32, axis.y as f32, axis.z as f32);
    match g.kind {
        JointKind::Prismatic => {
            let at = child.position().translation;
            (child.linvel() - parent.velocity_at_point(at)).dot(axis)
        }
        _ => (child.angvel() - parent.angvel()).dot(axis),
    }
}

impl Robot {
    /// One physics step of the kinematic drive: the ramp's next set point, and every kinematic
    /// body sent to its pose there (rapier moves it during the step, with the matching
    /// velocity for contacts).
    pub(crate) fn drive_kinematic(&mut self, bodies: &mut RigidBodySet, dt: f32) {
        let Some(arm) = self.kinematic.as_mut() else {
            return;
        };
        let target: Vec<f64> = arm
            .ramp_joints
            .iter()
            .map(|&j| self.targets[j] as f64)
            .collect();
        let Some(next) = arm.ramp.next(&target) else {
            return;
        };
        for (&j, &p) in arm.ramp_joints.iter().zip(&next) {
            // Without a lag `follow` is 1 and the joint lands exactly on the set point.
            let p = if arm.follow < 1.0 {
                arm.q[j] + arm.follow * (p as f32 - arm.q[j])
            } else {
                p as f32
            };
            arm.qd[j] = (p - arm.q[j]) / dt;
            arm.q[j] = p;
        }
        let root = pose_to_iso(bodies[self.bodies[0]].position());
        let poses = body_poses(root, &self.geometry, self.bodies.len(), &arm.q);
        for (g, impulse) in self.geometry.iter().zip(&arm.impulse) {
            if impulse.is_none() {
                let pose = iso_to_pose(&poses[g.child_body]);
                bodies[self.bodies[g.child_body]].set_next_kinematic_position(pose);
            }
        }
    }
}
