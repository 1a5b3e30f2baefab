//! Forward and inverse kinematics of a serial chain, in f64, straight from the robot model.
//!
//! Written here rather than taken from rapier's multibody IK because that solver's Jacobian refers
//! to each body's centre of mass (not the target frame) and ignores joint limits; a planner needs
//! limit-aware solutions for an arbitrary tool frame, independent of the physics state.

use crate::error::{Result, SimError};
use crate::model::{JointKind, Origin, RobotModel};
use rapier3d::na::{Isometry3, Matrix6, Matrix6xX, Translation3, UnitQuaternion, Vector3, Vector6};

/// An origin as an isometry: translation then fixed-axis roll-pitch-yaw (URDF convention).
pub fn origin_to_isometry(o: &Origin) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(o.xyz[0], o.xyz[1], o.xyz[2]),
        UnitQuaternion::from_euler_angles(o.rpy[0], o.rpy[1], o.rpy[2]),
    )
}

#[derive(Clone, Debug)]
struct ChainJoint {
    origin: Isometry3<f64>,
    axis: Vector3<f64>,
    kind: JointKind,
    /// Position of this joint's value in the chain's joint vector, `None` for fixed joints.
    dof: Option<usize>,
    /// The link this joint moves (index into the model's links).
    child: usize,
}

/// The joints from the root link to a tip frame, with the movable ones as the joint vector.
#[derive(Clone, Debug)]
pub struct SerialChain {
    joints: Vec<ChainJoint>,
    /// Names of the movable joints, in joint-vector order.
    pub joint_names: Vec<String>,
    /// `(lower, upper)` for each movable joint.
    pub limits: Vec<(f64, f64)>,
    /// Extra transform from the tip link to the tool frame.
    pub tool: Isometry3<f64>,
}

impl SerialChain {
    /// The chain from `model`'s root to the link `tip`.
    pub fn new(model: &RobotModel, tip: &str) -> Result<Self> {
        let tip_index = model.link_index(tip).ok_or_else(|| {
            SimError::urdf(&model.source_name, format!("link '{tip}'"), "no such link")
        })?;
        let mut joints = Vec::new();
        let mut joint_names = Vec::new();
        let mut limits = Vec::new();
        for j in model.chain_to(tip_index) {
            let joint = &model.joints[j];
            if joint.mimic.is_some() {
                return Err(SimError::urdf(
                    &model.source_name,
                    format!("joint '{}'", joint.name),
                    "a mimic joint cannot be part of a kinematic chain to the tool",
                ));
            }
            let dof = joint.kind.is_movable().then(|| {
                joint_names.push(joint.name.clone());
                let l = joint
                    .limits
                    .map(|l| (l.lower, l.upper))
                    .unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
                limits.push(l);
                joint_names.len() - 1
            });
            joints.push(ChainJoint {
                origin: origin_to_isometry(&joint.origin),
                axis: Vector3::from(joint.axis),
                kind: joint.kind,
                dof,
                child: joint.child,
            });
        }
        Ok(Self {
            joints,
            joint_names,
            limits,
            tool: Isometry3::identity(),
        })
    }

    fn joint_motion(joint: &ChainJoint, value: f64) -> Isometry3<f64> {
        match joint.kind {
            JointKind::Prismatic => Isometry3::from_parts(
                Translation3::from(joint.axis * value),
                UnitQuaternion::identity(),
            ),
            _ => Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_scaled_axis(joint.axis * value),
            ),
        }
    }

    /// Number of movable joints.
    pub fn dof(&self) -> usize {
        self.joint_names.len()
    }

    /// The tool frame pose (in the root link frame) at joint vector `q`.
    pub fn forward(&self, q: &[f64]) -> Isometry3<f64> {
        let mut pose = Isometry3::identity();
        for joint in &self.joints {
            pose *= joint.origin;
            if let Some(i) = joint.dof {
                pose *= Self::joint_motion(joint, q[i]);
            }
        }
        pose * self.tool
    }

    /// Visits the frame of every link along the chain at joint vector `q`, root to tip: `visit`
    /// gets the link's index in the model and its pose in the root link's frame (the tool
    /// offset is not applied).
    pub fn for_each_link(&self, q: &[f64], mut visit: impl FnMut(usize, &Isometry3<f64>)) {
        let mut pose = Isometry3::identity();
        for joint in &self.joints {
            pose *= joint.origin;
            if let Some(i) = joint.dof {
                pose *= Self::joint_motion(joint, q[i]);
            }
            visit(joint.child, &pose);
        }
    }

    /// The model's indices of the links the chain moves, root to tip.
    pub fn links(&self) -> Vec<usize> {
        self.joints.iter().map(|j| j.child).collect()
    }

    /// Geometric Jacobian (linear; angular rows, root frame) of the tool frame, from one pass
    /// along the chain: a revolute joint contributes `axis × (tool − joint)` and `axis`, a
    /// prismatic one `axis` and zero.
    fn jacobian(&self, q: &[f64]) -> (Isometry3<f64>, Matrix6xX<f64>) {
        let n = self.dof();
        let mut columns = Vec::with_capacity(n);
        let mut pose = Isometry3::identity();
        for joint in &self.joints {
            pose *= joint.origin;
            if let Some(i) = joint.dof {
                let axis = pose.rotation * joint.axis;
                columns.push((joint.kind, axis, pose.translation.vector));
                pose *= Self::joint_motion(joint, q[i]);
            }
        }
        let tool = pose * self.tool;
        let mut jac = Matrix6xX::zeros(n);
        for (i, (kind, axis, origin)) in columns.into_iter().enumerate() {
            let (linear, angular) = match kind {
                JointKind::Prismatic => (axis, Vector3::zeros()),
                _ => (axis.cross(&(tool.translation.vector - origin)), axis),
            };
            jac.fixed_view_mut::<3, 1>(0, i).copy_from(&linear);
            jac.fixed_view_mut::<3, 1>(3, i).copy_from(&angular);
        }
        (tool, jac)
    }

    /// Damped-least-squares IK from `seed`, staying within joint limits.
    ///
    /// Returns the joint vector whose tool pose is within `tolerance` (metres; radians for the
    /// orientation) of `target`, or an error with the residual. When the search from `seed` gets
    /// stuck against a limit, it restarts with the last joint (the tool roll) turned by ±π/2 and
    /// ±π, which is where a local solver usually goes wrong on a six-axis arm.
    pub fn inverse(
        &self,
        target: &Isometry3<f64>,
        seed: &[f64],
        tolerance: f64,
    ) -> Result<Vec<f64>> {
        let first = self.solve(target, seed, tolerance, false);
        if first.is_ok() || seed.is_empty() {
            return first;
        }
        let last = seed.len() - 1;
        let half_pi = std::f64::consts::FRAC_PI_2;
        for shift in [half_pi, -half_pi, 2.0 * half_pi, -2.0 * half_pi] {
            let mut restart = seed.to_vec();
            restart[last] += shift;
            let (lo, hi) = self.limits[last];
            if restart[last] < lo || restart[last] > hi {
                continue;
            }
            if let Ok(q) = self.solve(target, &restart, tolerance, false) {
                return Ok(q);
            }
        }
        first
    }

    /// Damped-least-squares IK that leaves the rotation about the root frame's z axis free:
    /// the tool's axis is held (a top-down tool stays top-down) and its yaw is wherever the
    /// joints take it, the last joint held at its limit when the target's yaw lies beyond it.
    /// For a yaw the wrist cannot reach, so that the arm still moves to the position.
    pub fn inverse_free_yaw(
        &self,
        target: &Isometry3<f64>,
        seed: &[f64],
        tolerance: f64,
    ) -> Result<Vec<f64>> {
        self.solve(target, seed, tolerance, true)
    }

    /// The damped-least-squares search; `free_yaw` drops the z row of the rotation error.
    fn solve(
        &self,
        target: &Isometry3<f64>,
        seed: &[f64],
        tolerance: f64,
        free_yaw: bool,
    ) -> Result<Vec<f64>> {
        let n = self.dof();
        if seed.len() != n {
            return Err(SimError::Command(format!(
                "IK seed has {} values, the chain has {n} joints",
                seed.len()
            )));
        }
        let mut q: Vec<f64> = seed
            .iter()
            .zip(&self.limits)
            .map(|(v, (lo, hi))| v.clamp(*lo, *hi))
            .collect();
        let mut error = f64::INFINITY;
        for _ in 0..200 {
            let (pose, mut jac) = self.jacobian(&q);
            let mut e = pose_error(&pose, target);
            if free_yaw {
                e[5] = 0.0;
                jac.row_mut(5).fill(0.0);
            }
            error = e.norm();
            if e.fixed_rows::<3>(0).norm() < tolerance && e.fixed_rows::<3>(3).norm() < tolerance {
                return Ok(q);
            }
            // dq = Jᵀ (J Jᵀ + λ² I)⁻¹ e, with damping growing near singularities.
            let lambda2 = 1e-4 + 1e-2 * error.min(1.0);
            let jjt: Matrix6<f64> = &jac * jac.transpose() + Matrix6::identity() * lambda2;
            let Some(inv) = jjt.try_inverse() else {
                break;
            };
            let dq = jac.transpose() * (inv * e);
            // Limit the step so the linearisation stays valid.
            let scale = (0.3 / dq.amax()).min(1.0);
            for i in 0..n {
                let (lo, hi) = self.limits[i];
                q[i] = (q[i] + dq[i] * scale).clamp(lo, hi);
            }
        }
        Err(SimError::Ik(format!(
            "residual {error:.4} after 200 iterations (target {:?})",
            target.translation.vector.as_slice()
        )))
    }
}

/// The 6-vector (position error; rotation error as a scaled axis), world frame.
pub fn pose_error(current: &Isometry3<f64>, target: &Isometry3<f64>) -> Vector6<f64> {
    let dp = target.translation.vector - current.translation.vector;
    let dr = (target.rotation * current.rotation.inverse()).scaled_axis();
    Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The analytic Jacobian against central differences of `forward`, with a tool offset.
    #[test]
    fn jacobian_matches_finite_differences() {
        let model = crate::assets::fr5().unwrap();
        let mut chain = SerialChain::new(&model, "tool0").unwrap();
        chain.tool = Isometry3::from_parts(
            Translation3::new(0.01, -0.02, 0.1),
            UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3),
        );
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..20 {
            let q: Vec<f64> = (0..6).map(|_| rng.random_range(-2.0..2.0)).collect();
            let (pose, jac) = chain.jacobian(&q);
            assert!(
                (pose.translation.vector - chain.forward(&q).translation.vector).norm() < 1e-12
            );
            let h = 1e-6;
            for i in 0..6 {
                let (mut plus, mut minus) = (q.clone(), q.clone());
                plus[i] += h;
                minus[i] -= h;
                let (p, m) = (chain.forward(&plus), chain.forward(&minus));
                let dp = (p.translation.vector - m.translation.vector) / (2.0 * h);
                let dr = (p.rotation * m.rotation.inverse()).scaled_axis() / (2.0 * h);
                for r in 0..3 {
                    assert!((jac[(r, i)] - dp[r]).abs() < 1e-6, "linear {r},{i}");
                    assert!((jac[(r + 3, i)] - dr[r]).abs() < 1e-6, "angular {r},{i}");
                }
            }
        }
    }
}
