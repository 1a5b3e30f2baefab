//! Observation presets. Positions and orientations are expressed in the arm base frame, so the
//! base's placement in the world does not change what the policy sees.
//!
//! `seed23` (the design's layout, in this order):
//!
//! | index | content |
//! |---|---|
//! | 0–5 | joint angles j1…j6 (rad) |
//! | 6–8 | EE (TCP) position (m) |
//! | 9–11 | EE orientation, roll-pitch-yaw (rad) |
//! | 12–14 | object position (m) |
//! | 15–18 | object quaternion (x, y, z, w) |
//! | 19–21 | EE linear velocity (m/s) |
//! | 22 | gripper opening (m) |
//!
//! `rich` (33 values plus the previous action: 40 in joint mode, 38 in Cartesian mode):
//!
//! | index | content |
//! |---|---|
//! | 0–5 | joint angles (rad) |
//! | 6–11 | joint velocities (rad/s) |
//! | 12–14 | EE position (m) |
//! | 15–20 | EE orientation: first two columns of its rotation matrix (continuous, unlike Euler angles near a top-down pose) |
//! | 21–23 | object position (m) |
//! | 24–25 | sin and cos of 4 × (object yaw − EE yaw): the cube's fourfold symmetry folded out |
//! | 26–28 | EE → object vector (m) |
//! | 29 | object lift above its resting height (m) |
//! | 30 | gripper opening (m) |
//! | 31–32 | left / right pad touches the object (0 or 1) |
//! | 33… | previous action, normalised to [-1, 1] (7 values in joint mode, 5 in Cartesian mode) |

use crate::config::{ObservationNoise, ObservationPreset};
use fairgrasp_sim::rapier3d::na::{Isometry3, Point3, Vector3};
use fairgrasp_sim::scene::Scene;
use std::ops::Range;

/// Which noise standard deviation applies to a range of observation entries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum NoiseGroup {
    JointPosition,
    JointVelocity,
    EePosition,
    EeOrientation,
    EeVelocity,
    ObjectPosition,
    ObjectOrientation,
    Gripper,
    /// Derived or exact quantities (contact flags, previous action): no noise of their own.
    None,
}

impl NoiseGroup {
    pub(crate) fn std(self, noise: &ObservationNoise) -> f32 {
        match self {
            NoiseGroup::JointPosition => noise.joint_position,
            NoiseGroup::JointVelocity => noise.joint_velocity,
            NoiseGroup::EePosition => noise.ee_position,
            NoiseGroup::EeOrientation => noise.ee_orientation,
            NoiseGroup::EeVelocity => noise.ee_velocity,
            NoiseGroup::ObjectPosition => noise.object_position,
            NoiseGroup::ObjectOrientation => noise.object_orientation,
            NoiseGroup::Gripper => noise.gripper_opening,
            NoiseGroup::None => 0.0,
        }
    }
}

/// Observation length of a preset for a six-joint arm and an action of `action_dim` values.
pub fn observation_dim(preset: ObservationPreset, action_dim: usize) -> usize {
    match preset {
        ObservationPreset::Seed23 => 23,
        ObservationPreset::Rich => 33 + action_dim,
    }
}

/// The noise groups of a preset's entries, as ranges.
pub(crate) fn noise_groups(
    preset: ObservationPreset,
    action_dim: usize,
) -> Vec<(Range<usize>, NoiseGroup)> {
    use NoiseGroup::*;
    match preset {
        ObservationPreset::Seed23 => vec![
            (0..6, JointPosition),
            (6..9, EePosition),
            (9..12, EeOrientation),
            (12..15, ObjectPosition),
            (15..19, ObjectOrientation),
            (19..22, EeVelocity),
            (22..23, Gripper),
        ],
        ObservationPreset::Rich => vec![
            (0..6, JointPosition),
            (6..12, JointVelocity),
            (12..15, EePosition),
            (15..21, EeOrientation),
            (21..24, ObjectPosition),
            (24..26, ObjectOrientation),
            (26..29, ObjectPosition),
            (29..30, ObjectPosition),
            (30..31, Gripper),
            (31..33 + action_dim, None),
        ],
    }
}

fn push3(out: &mut Vec<f32>, v: &Vector3<f64>) {
    out.extend([v.x as f32, v.y as f32, v.z as f32]);
}

/// Reads the scene into an observation vector. `previous_action` must already be normalised to
/// [-1, 1] (only the rich preset uses it).
pub(crate) fn observe(
    scene: &Scene,
    preset: ObservationPreset,
    previous_action: &[f32],
    out: &mut Vec<f32>,
) {
    out.clear();
    let base_inv: Isometry3<f64> = scene.base_pose().inverse();
    let q = scene.arm_positions();
    let tcp = base_inv * scene.tcp_pose();
    let object = scene.object_state(0);
    let object_pose = base_inv * object.pose;
    let (tcp_v, _) = scene.link_velocity("tcp").unwrap_or(([0.0; 3], [0.0; 3]));
    let tcp_v = base_inv.rotation * Vector3::from(tcp_v);
    match preset {
        ObservationPreset::Seed23 => {
            out.extend_from_slice(&q);
            push3(out, &tcp.translation.vector);
            let (r, p, y) = tcp.rotation.euler_angles();
            out.extend([r as f32, p as f32, y as f32]);
            push3(out, &object_pose.translation.vector);
            let oq = object_pose.rotation.quaternion();
            out.extend([oq.i as f32, oq.j as f32, oq.k as f32, oq.w as f32]);
            push3(out, &tcp_v);
            out.push(scene.gripper_opening());
        }
        ObservationPreset::Rich => {
            out.extend_from_slice(&q);
            out.extend_from_slice(&scene.arm_velocities());
            push3(out, &tcp.translation.vector);
            let m = tcp.rotation.to_rotation_matrix();
            for c in 0..2 {
                push3(out, &m.matrix().column(c).into_owned());
            }
            push3(out, &object_pose.translation.vector);
            let relative_yaw =
                object_pose.rotation.euler_angles().2 - tcp.rotation.euler_angles().2;
            out.extend([
                (4.0 * relative_yaw).sin() as f32,
                (4.0 * relative_yaw).cos() as f32,
            ]);
            let to_object = object_pose.translation.vector - tcp.translation.vector;
            push3(out, &to_object);
            out.push((object.pose.translation.z - scene.object_rest_height(0)) as f32);
            out.push(scene.gripper_opening());
            let contacts = scene.finger_contacts(0);
            out.extend(contacts.map(|c| if c { 1.0 } else { 0.0 }));
            out.extend_from_slice(previous_action);
        }
    }
    debug_assert_eq!(out.len(), observation_dim(preset, previous_action.len()));
}

/// The object centre seen from the TCP frame (used by the reward and the scripted policies).
pub fn object_in_tcp_frame(scene: &Scene) -> Vector3<f64> {
    scene
        .tcp_pose()
        .inverse_transform_point(&Point3::from(scene.object_state(0).pose.translation.vector))
        .coords
}
