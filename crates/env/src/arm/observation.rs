//! Writing observations: each value goes in with its noise group, so domain randomisation knows
//! which standard deviation applies to which entries without a hand-kept index table.

use crate::arm::config::ObservationNoise;
use crate::arm::state::ArmState;
use fairgrasp_sim::rapier3d::na::Vector3;
use std::ops::Range;

/// Which noise standard deviation applies to a range of observation entries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoiseGroup {
    /// Joint angles (rad).
    JointPosition,
    /// Joint speeds (rad/s).
    JointVelocity,
    /// TCP position (m).
    EePosition,
    /// TCP orientation (Euler angles or rotation-matrix entries).
    EeOrientation,
    /// TCP linear velocity (m/s).
    EeVelocity,
    /// Object position and lengths measured from it: TCP→object, lift, object→goal (m).
    ObjectPosition,
    /// Object orientation (quaternion or rotation features).
    ObjectOrientation,
    /// Gripper opening (m).
    Gripper,
    /// Exact or derived quantities (flags, goals, the previous action): no noise of their own.
    None,
}

impl NoiseGroup {
    /// The largest magnitude a value of this group takes: the observation space's bound
    /// (values beyond it are clipped). Physical bounds with room to spare, so that only physics
    /// gone wild is ever clipped: the FR5's joints turn at most ±265° (4.6 rad) at up to
    /// 180°/s (3.1 rad/s) and it reaches 0.92 m; rotation-matrix entries, quaternions, sines
    /// and cosines lie in [-1, 1] and Euler angles in [-π, π]; flags, normalised previous
    /// actions, goals, bins and object sizes stay within a few metres or units.
    pub fn bound(self) -> f32 {
        match self {
            NoiseGroup::JointPosition => std::f32::consts::TAU,
            NoiseGroup::JointVelocity => 50.0,
            NoiseGroup::EePosition => 5.0,
            NoiseGroup::EeOrientation => std::f32::consts::PI,
            NoiseGroup::EeVelocity => 20.0,
            NoiseGroup::ObjectPosition => 10.0,
            NoiseGroup::ObjectOrientation => 1.0,
            NoiseGroup::Gripper => 1.0,
            NoiseGroup::None => 10.0,
        }
    }

    /// The standard deviation of this group's noise under `noise`; 0 for [`NoiseGroup::None`].
    pub fn std(self, noise: &ObservationNoise) -> f32 {
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

/// Appends observation values, recording their noise groups when asked to (once, when the
/// environment is built).
pub struct ObsWriter<'a> {
    out: &'a mut Vec<f32>,
    groups: Option<&'a mut Vec<(Range<usize>, NoiseGroup)>>,
}

impl<'a> ObsWriter<'a> {
    /// Writes into `out` (cleared first).
    pub fn new(out: &'a mut Vec<f32>) -> Self {
        out.clear();
        Self { out, groups: None }
    }

    /// Writes into `out` and records each value's group in `groups`.
    pub fn recording(
        out: &'a mut Vec<f32>,
        groups: &'a mut Vec<(Range<usize>, NoiseGroup)>,
    ) -> Self {
        out.clear();
        groups.clear();
        Self {
            out,
            groups: Some(groups),
        }
    }

    /// Appends `values`, all in `group`.
    pub fn push(&mut self, group: NoiseGroup, values: &[f32]) {
        let start = self.out.len();
        self.out.extend_from_slice(values);
        if let Some(groups) = &mut self.groups {
            match groups.last_mut() {
                Some((range, g)) if *g == group && range.end == start => range.end = self.out.len(),
                _ => groups.push((start..self.out.len(), group)),
            }
        }
    }

    /// Appends one value in `group`.
    pub fn push1(&mut self, group: NoiseGroup, value: f32) {
        self.push(group, &[value]);
    }

    /// Appends a vector's x, y, z as f32, in `group`.
    pub fn push3(&mut self, group: NoiseGroup, v: &Vector3<f64>) {
        self.push(group, &[v.x as f32, v.y as f32, v.z as f32]);
    }

    /// Number of values written so far.
    pub fn len(&self) -> usize {
        self.out.len()
    }

    /// Whether no value is written yet.
    pub fn is_empty(&self) -> bool {
        self.out.is_empty()
    }
}

/// Joint angles and speeds, TCP position and orientation (two rotation-matrix columns:
/// continuous, unlike Euler angles near a top-down pose): how the `rich` layout and the pixel
/// modes' arm observation begin.
fn joints_and_tcp(s: &ArmState, out: &mut ObsWriter) {
    use NoiseGroup::*;
    out.push(JointPosition, &s.q);
    out.push(JointVelocity, &s.qd);
    out.push3(EePosition, &s.tcp.translation.vector);
    let m = s.tcp.rotation.to_rotation_matrix();
    for c in 0..2 {
        out.push3(EeOrientation, &m.matrix().column(c).into_owned());
    }
}

/// The `rich` layout around object `i` (33 values plus the previous action; docs/tasks.md):
/// joints, velocities, TCP position and orientation (two rotation-matrix columns: continuous,
/// unlike Euler angles near a top-down pose), the object's position, its yaw relative to the
/// TCP with the cube's fourfold symmetry folded out, the TCP→object vector, the lift, the
/// gripper opening, the pad contacts and the previous action.
pub(crate) fn rich_observation(
    s: &ArmState,
    i: usize,
    previous_action: &[f32],
    out: &mut ObsWriter,
) {
    use NoiseGroup::*;
    let object = &s.objects[i];
    joints_and_tcp(s, out);
    out.push3(ObjectPosition, &object.pose.translation.vector);
    let yaw = s.relative_yaw(i);
    out.push(
        ObjectOrientation,
        &[(4.0 * yaw).sin() as f32, (4.0 * yaw).cos() as f32],
    );
    out.push3(ObjectPosition, &s.tcp_to_object(i));
    out.push1(ObjectPosition, s.lift(i) as f32);
    out.push1(Gripper, s.gripper_opening);
    out.push(
        None,
        &object.pad_contacts.map(|c| if c { 1.0 } else { 0.0 }),
    );
    out.push(None, previous_action);
}

/// Object `i`'s shape block (5 values, after the `rich` layout where shapes vary): its half
/// extents and sin/cos of 2 × its yaw relative to the TCP (a box's twofold symmetry folded out).
pub(crate) fn shape_observation(s: &ArmState, i: usize, out: &mut ObsWriter) {
    let yaw = s.relative_yaw(i);
    out.push(NoiseGroup::None, &s.objects[i].half_extents);
    out.push(
        NoiseGroup::ObjectOrientation,
        &[(2.0 * yaw).sin() as f32, (2.0 * yaw).cos() as f32],
    );
}

/// What the real arm reports, for pixel policies (the `[camera]` modes): joints, joint speeds,
/// TCP position and orientation (two rotation-matrix columns), the gripper opening and the
/// previous action (22 values plus the action). Nothing about the objects: the camera shows them.
pub(crate) fn arm_observation(s: &ArmState, previous_action: &[f32], out: &mut ObsWriter) {
    use NoiseGroup::*;
    joints_and_tcp(s, out);
    out.push1(Gripper, s.gripper_opening);
    out.push(None, previous_action);
}
