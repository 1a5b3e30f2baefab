//! The real arm's readings as the policy's [`ArmState`]: the controller's joints through the
//! calibration, the TCP from the policy's own kinematic chain (so the tool frame set on the
//! pendant does not matter), the object from the pose source, velocities by differences. Under
//! a speed scale `s` every velocity is divided by `s`: the policy sees the motion in its
//! trained time.

use super::model_io::ModelIo;
use crate::calibration::Calibration;
use crate::pose_source::PoseMessage;
use crate::robot::RobotState;
use fairgrasp_env::arm::ArmState;
use fairgrasp_env::sim::rapier3d::na::{Isometry3, Vector3};
use std::time::Instant;

/// Gripper position (% open) below which a closed gripper that has stopped is taken to hold
/// nothing: fully closed reads 0–4 % on the twin (finger jitter), and the simulator's grasp
/// rule asks for more than 5 mm of the 90 mm stroke.
const HOLDING_MIN_PERCENT: u8 = 6;
/// How far (% of the stroke) the fingers must have closed before a stop counts as a grasp, so
/// the first reading after a close command (fingers not yet moving) is not one.
const HOLDING_MIN_TRAVEL: u8 = 5;

/// Builds [`ArmState`]s from successive readings.
pub struct StateEstimator {
    previous: Option<(Instant, Vector3<f64>, Vector3<f64>)>,
    /// The gripper position (%) when the close command was first seen, and at the last reading.
    closing_from: Option<u8>,
    last_gripper: Option<u8>,
    /// Velocities are divided by this (the speed scale).
    time_scale: f64,
}

impl StateEstimator {
    /// `speed_scale`: the deployment's (0, 1]; 1 reports velocities as measured.
    pub fn new(speed_scale: f64) -> Self {
        Self {
            time_scale: speed_scale,
            previous: None,
            closing_from: None,
            last_gripper: None,
        }
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
        let qd: Vec<f32> = (calibration.speeds_to_sim(&robot.joint_speeds_deg).iter())
            .map(|&v| (v as f64 / self.time_scale) as f32)
            .collect();
        let q64: Vec<f64> = q.iter().map(|&v| v as f64).collect();
        let tcp: Isometry3<f64> = io.chain.forward(&q64);
        let object_pose = object.isometry();
        let (tcp_p, obj_p) = (tcp.translation.vector, object_pose.translation.vector);
        let (tcp_linvel, obj_linvel) = match self.previous {
            Some((t, tp, op)) => {
                let dt = now.saturating_duration_since(t).as_secs_f64();
                if dt > 1e-4 {
                    let dt = dt * self.time_scale;
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
        // The real gripper reports no pad contacts: a closing gripper that stopped partway
        // holds something (both pads). The controller's "motion done" comes only after its
        // own stall timeout (150 ms on the twin, 4–5 control steps), while the simulator's
        // pads report contact at once; a policy that sees no contact for that long reopens
        // (session 6: 6/10 twin grasps, the failures all open-close cycles with the fingers
        // on the cube). So a closing gripper whose fingers travelled and then stopped between
        // two readings counts as holding too.
        let position = robot.gripper_position;
        let from = if gripper_closing {
            // The reading before the close command was seen: the fingers can cover most of
            // the stroke within one control step.
            *self
                .closing_from
                .get_or_insert(self.last_gripper.unwrap_or(position))
        } else {
            self.closing_from = None;
            position
        };
        let travelled = position.saturating_add(HOLDING_MIN_TRAVEL) <= from;
        let stopped = self.last_gripper.is_some_and(|last| position >= last);
        self.last_gripper = Some(position);
        // Travel is asked of "motion done" too: the first readings after a close command can
        // still carry the open move's "done".
        // And one whose fingers are as far apart as the object is wide (between its narrowest
        // and widest extent across the table, ±3 mm) is touching it, as the simulator's pads
        // report at contact. Below that band the fingers passed it: nothing between them.
        let reading0 = &nominal.objects[0];
        let (a, b) = (reading0.half_extents[0], reading0.half_extents[1]);
        let at_width = (2.0 * a.min(b) - 0.003..=2.0 * a.max(b) + 0.003).contains(&opening);
        let holding = gripper_closing
            && travelled
            && position >= HOLDING_MIN_PERCENT
            && (robot.gripper_motion_done || stopped || at_width);
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

#[cfg(test)]
mod tests {
    use super::*;
    use fairgrasp_env::GraspConfig;
    use std::time::Duration;

    fn setup() -> (ModelIo, Calibration, PoseMessage) {
        let io = ModelIo::for_config(GraspConfig::default()).unwrap();
        let calibration = Calibration::identity(&io.limits_rad);
        let cube = PoseMessage {
            position: [0.45, 0.0, 0.025],
            orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
            stamp: None,
        };
        (io, calibration, cube)
    }

    /// The pads of the estimated state while the gripper, commanded closed, reads `positions`
    /// (% open) with the controller's "motion done" given.
    fn pads(positions: &[(u8, bool)]) -> Vec<bool> {
        let (io, calibration, cube) = setup();
        let mut estimator = StateEstimator::new(1.0);
        let t0 = Instant::now();
        let home = calibration.to_robot(&io.nominal.q);
        positions
            .iter()
            .enumerate()
            .map(|(k, &(position, done))| {
                let robot = RobotState {
                    joints_deg: home,
                    gripper_position: position,
                    gripper_motion_done: done,
                    ..RobotState::default()
                };
                let now = t0 + Duration::from_millis(33 * k as u64);
                let s = estimator.estimate(&io, &calibration, &robot, &cube, true, now);
                s.objects[0].pad_contacts[0]
            })
            .collect()
    }

    #[test]
    fn fingers_stopped_partway_hold_at_once_without_waiting_for_motion_done() {
        // Closing from open: moving, moving, stopped at 88 % (a cube turned across the
        // fingers), still stopped: held from the second stopped reading.
        let held = pads(&[
            (100, true),
            (95, false),
            (90, false),
            (88, false),
            (88, false),
        ]);
        assert_eq!(held, [false, false, false, false, true]);
        // Fingers at the 5 cm cube's width (58 % of 9 cm): touching at once.
        let held = pads(&[(100, true), (80, false), (58, false), (58, false)]);
        assert_eq!(held, [false, false, true, true]);
        // Even when the first reading after the command finds them there already.
        assert_eq!(pads(&[(100, true), (58, false)]), [false, true]);
    }

    #[test]
    fn a_stale_motion_done_or_a_fully_closed_gripper_is_not_a_grasp() {
        // The open move's "done" still showing right after the close command.
        assert_eq!(pads(&[(100, true), (100, true)]), [false, false]);
        // Closed on nothing, or stopped well inside the object's width (on an edge, or on
        // nothing at 10 %) while still moving. (A reading taken as the fingers pass through the
        // object's width would count: one control step of contact, where the simulator shows
        // none.)
        assert_eq!(
            pads(&[(100, true), (70, false), (0, true), (0, true)]),
            [false; 4]
        );
        assert_eq!(pads(&[(100, true), (30, false), (11, false)]), [false; 3]);
        // Fully closed reads a few percent (finger jitter): stopped there, nothing is held.
        assert_eq!(
            pads(&[(100, true), (40, false), (4, false), (4, true)]),
            [false; 4]
        );
    }

    #[test]
    fn velocities_are_seen_in_the_policy_s_time_under_a_speed_scale() {
        let (io, calibration, cube) = setup();
        let home = calibration.to_robot(&io.nominal.q);
        let robot = RobotState {
            joints_deg: home,
            joint_speeds_deg: [10.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ..RobotState::default()
        };
        let t0 = Instant::now();
        let mut moved = cube.clone();
        moved.position[0] += 0.001;
        let speeds: Vec<(f32, f64)> = [1.0, 0.25]
            .iter()
            .map(|&scale| {
                let mut e = StateEstimator::new(scale);
                e.estimate(&io, &calibration, &robot, &cube, false, t0);
                let t1 = t0 + Duration::from_millis(100);
                let s = e.estimate(&io, &calibration, &robot, &moved, false, t1);
                (s.qd[0], s.objects[0].linvel.x)
            })
            .collect();
        assert!((speeds[0].0 - 10f32.to_radians()).abs() < 1e-5);
        assert!((speeds[1].0 - 4.0 * speeds[0].0).abs() < 1e-5);
        assert!((speeds[0].1 - 0.01).abs() < 1e-6 && (speeds[1].1 - 0.04).abs() < 1e-6);
    }
}
