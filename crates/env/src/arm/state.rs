//! The arm's state as plain numbers, in the arm base frame: what an observation and the action
//! mapping are computed from. The simulator fills it ([`ArmState::from_scene`]); on the real
//! arm, the controller's state stream and the user's perception fill the same struct, so the
//! policy sees the same layout in both worlds.

use fairgrasp_sim::pick::closed_on_object;
use fairgrasp_sim::rapier3d::na::{Isometry3, Vector3};
use fairgrasp_sim::scene::Scene;

/// One object, in the arm base frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectReading {
    /// Pose of the object's body (m, unit quaternion).
    pub pose: Isometry3<f64>,
    /// Linear velocity (m/s).
    pub linvel: Vector3<f64>,
    /// Height of the centre when the object rests upright on the table (m, base frame z).
    pub rest_z: f64,
    /// Whether the left and right finger pads touch it (on the real arm: the gripper's
    /// object-detection status, for both pads).
    pub pad_contacts: [bool; 2],
    /// Half extents of the object's bounding box in its own frame (m).
    pub half_extents: [f32; 3],
}

/// Everything a policy may observe about the arm and the objects (base frame, SI units).
#[derive(Clone, Debug, PartialEq)]
pub struct ArmState {
    /// Joint angles (rad), base to flange.
    pub q: Vec<f32>,
    /// Joint velocities (rad/s).
    pub qd: Vec<f32>,
    /// TCP pose (the point between the finger pads).
    pub tcp: Isometry3<f64>,
    /// TCP linear velocity (m/s).
    pub tcp_linvel: Vector3<f64>,
    /// Distance between the finger pads (m).
    pub gripper_opening: f32,
    /// Largest opening of the gripper (m).
    pub gripper_max_opening: f32,
    /// The gripper is commanded closed.
    pub gripper_closing: bool,
    /// Height of the table top (m, base frame z).
    pub table_z: f64,
    /// Every object of the scene, in scene order.
    pub objects: Vec<ObjectReading>,
}

impl ArmState {
    /// Reads the simulated scene.
    pub fn from_scene(scene: &Scene) -> Self {
        let base_inv = scene.base_pose().inverse();
        let (tcp_v, _) = scene.link_velocity("tcp").unwrap_or(([0.0; 3], [0.0; 3]));
        let base_z = scene.base_pose().translation.z;
        let objects = (0..scene.num_objects())
            .map(|i| {
                let s = scene.object_state(i);
                ObjectReading {
                    pose: base_inv * s.pose,
                    linvel: base_inv.rotation * Vector3::from(s.linvel),
                    rest_z: scene.object_rest_height(i) - base_z,
                    pad_contacts: scene.finger_contacts(i),
                    half_extents: scene.object_half_extents(i),
                }
            })
            .collect();
        Self {
            q: scene.arm_positions(),
            qd: scene.arm_velocities(),
            tcp: base_inv * scene.tcp_pose(),
            tcp_linvel: base_inv.rotation * Vector3::from(tcp_v),
            gripper_opening: scene.gripper_opening(),
            gripper_max_opening: scene.max_opening(),
            gripper_closing: scene.gripper_commanded_closed(),
            table_z: scene.table_top() as f64 - base_z,
            objects,
        }
    }

    /// The object's centre seen from the TCP (m).
    pub fn tcp_to_object(&self, i: usize) -> Vector3<f64> {
        self.objects[i].pose.translation.vector - self.tcp.translation.vector
    }

    /// Object `i`'s yaw relative to the TCP's (rad).
    pub fn relative_yaw(&self, i: usize) -> f64 {
        self.objects[i].pose.rotation.euler_angles().2 - self.tcp.rotation.euler_angles().2
    }

    /// Lift of object `i` above its resting height (m).
    pub fn lift(&self, i: usize) -> f64 {
        self.objects[i].pose.translation.z - self.objects[i].rest_z
    }

    /// Object `i` is held: the gripper is commanded closed, both pads touch it and the fingers
    /// are stopped by it (the scripted pick's [`closed_on_object`]).
    pub fn grasped(&self, i: usize) -> bool {
        closed_on_object(
            self.gripper_closing,
            self.objects[i].pad_contacts,
            self.gripper_opening,
        )
    }
}
