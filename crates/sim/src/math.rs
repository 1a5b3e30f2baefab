//! Conversions between the planner's f64 nalgebra isometries and rapier's f32 glam poses.

use rapier3d::math::{Pose, Rotation, Vector};
use rapier3d::na::{Isometry3, Quaternion, Translation3, UnitQuaternion};

/// nalgebra f64 isometry → rapier pose.
pub fn iso_to_pose(iso: &Isometry3<f64>) -> Pose {
    let t = iso.translation.vector;
    let q = iso.rotation.quaternion();
    Pose::from_parts(
        Vector::new(t.x as f32, t.y as f32, t.z as f32),
        Rotation::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32).normalize(),
    )
}

/// rapier pose → nalgebra f64 isometry.
pub fn pose_to_iso(pose: &Pose) -> Isometry3<f64> {
    let t = pose.translation;
    let q = pose.rotation;
    Isometry3::from_parts(
        Translation3::new(t.x as f64, t.y as f64, t.z as f64),
        UnitQuaternion::from_quaternion(Quaternion::new(
            q.w as f64, q.x as f64, q.y as f64, q.z as f64,
        )),
    )
}

/// Yaw (rotation about world z) of a rotation, in (-π, π].
pub fn yaw_of(rotation: &UnitQuaternion<f64>) -> f64 {
    rotation.euler_angles().2
}
