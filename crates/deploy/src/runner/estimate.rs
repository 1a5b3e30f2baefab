//! The real arm's readings as the policy's [`ArmState`]: the controller's joints through the
//! calibration, the TCP from the policy's own kinematic chain (so the tool frame set on the
//! pendant does not matter), the object from the pose source, velocities by differences.

use super::model_io::ModelIo;
use crate::calibration::Calibration;
use crate::pose_source::PoseMessage;
use crate::robot::RobotState;
use fairgrasp_env::arm::ArmState;
use fairgrasp_env::sim::rapier3d::na::{Isometry3, Vector3};
use std::time::Instant;

/// Gripper position (% open) below which a closed gripper that has stopped is taken to hold
/// the object: fully closed (0 %) means it closed on nothing.
const HOLDING_MIN_PERCENT: u8 = 2;

/// Builds [`ArmState`]s from successive readings.
pub struct StateEstimator {
    previous: Option<(Instant, Vector3<f64>, Vector3<f64>)>,
}

impl Default for StateEstimator {
    fn default() -> Self {
        Self::new()
    }
}

impl StateEstimator {
    pub fn new() -> Self {
        Self { previous: None }
    }

    /// The state at `now` from the robot's report, the object's pose and whether the gripper
    /// is commanded closed.
    pub fn estimate(
        &mut self,
        io: &ModelIo,
        calibration: &Calibration,
        robot: &RobotState,
        object: &PoseMessage,
        gripper_closing: bool,
        now: Instant,
    ) -> ArmState {
        let q = calibration.to_sim(&robot.joints_deg);
        let qd = calibration.speeds_to_sim(&robot.joint_speeds_deg);
        let q64: Vec<f64> = q.iter().map(|&v| v as f64).collect();
        let tcp: Isometry3<f64> = io.chain.forward(&q64);
        let object_pose = object.isometry();
        let (tcp_p, obj_p) = (tcp.translation.vector, object_pose.translation.vector);
        let (tcp_linvel, obj_linvel) = match self.previous {
            Some((t, tp, op)) => {
                let dt = now.saturating_duration_since(t).as_secs_f64();
                if dt > 1e-4 {
                    ((tcp_p - tp) / dt, (obj_p - op) / dt)
                } else {
                    (Vector3::zeros(), Vector3::zeros())
                }
            }
            None => (Vector3::zeros(), Vector3::zeros()),
        };
        self.previous = Some((now, tcp_p, obj_p));
        let nominal = &io.nominal;
        let max_opening = nominal.gripper_max_opening;
        let opening = max_opening * robot.gripper_position.min(100) as f32 / 100.0;
        // The real gripper reports no pad contacts: a closed gripper that stopped partway
        // holds something (both pads).
        let holding = gripper_closing
            && robot.gripper_motion_done
            && robot.gripper_position >= HOLDING_MIN_PERCENT;
        let mut reading = nominal.objects[0].clone();
        reading.pose = object_pose;
        reading.linvel = obj_linvel;
        reading.pad_contacts = [holding, holding];
        ArmState {
            q,
            qd,
            tcp,
            tcp_linvel,
            gripper_opening: opening,
            gripper_max_opening: max_opening,
            gripper_closing,
            table_z: nominal.table_z,
            objects: vec![reading],
        }
    }
}
