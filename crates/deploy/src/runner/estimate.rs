//! The real arm's readings as the policy's [`ArmState`]: the controller's report through the
//! calibration into the simulator's joint frame, then the env's own [`StateEstimator`] — the
//! code training builds the policy's observation with (`[readings]`). Under a speed scale `s`
//! every speed and time is seen in the policy's time: speeds divided by `s`, time multiplied
//! by it.

use super::model_io::ModelIo;
use crate::calibration::Calibration;
use crate::pose_source::PoseMessage;
use crate::robot::RobotState;
use fairgrasp_env::arm::{ArmState, ControllerReading, StateEstimator};
use std::time::Instant;

/// Builds [`ArmState`]s from successive robot states.
pub struct ArmReader {
    estimator: StateEstimator,
    previous: Option<Instant>,
    /// Speeds are divided by this and times multiplied (the speed scale).
    time_scale: f64,
}

impl ArmReader {
    /// `speed_scale`: the deployment's (0, 1]; 1 reports speeds as measured.
    pub fn new(speed_scale: f64) -> Self {
        Self {
            estimator: StateEstimator::new(),
            previous: None,
            time_scale: speed_scale,
        }
    }

    /// The robot's report as a controller reading in the simulator's joint frame and the
    /// policy's time.
    pub fn reading(&self, calibration: &Calibration, robot: &RobotState) -> ControllerReading {
        ControllerReading {
            joints_deg: calibration.to_sim_deg(&robot.joints_deg),
            joint_speeds_deg: (calibration
                .speeds_to_sim_deg(&robot.joint_speeds_deg)
                .iter())
            .map(|v| v / self.time_scale)
            .collect(),
            gripper_percent: robot.gripper_position,
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
        let dt = self
            .previous
            .map(|t| now.saturating_duration_since(t).as_secs_f64() * self.time_scale)
            .unwrap_or(0.0);
        self.previous = Some(now);
        let reading = self.reading(calibration, robot);
        self.estimator
            .estimate(&io.facts, &reading, object.isometry(), gripper_closing, dt)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fairgrasp_env::GraspConfig;
    use std::time::Duration;

    #[test]
    fn velocities_are_seen_in_the_policy_s_time_under_a_speed_scale() {
        let io = ModelIo::for_config(GraspConfig::default()).unwrap();
        let calibration = Calibration::identity(&io.limits_rad);
        let cube = PoseMessage {
            position: [0.45, 0.0, 0.025],
            orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
            stamp: None,
        };
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
                let mut e = ArmReader::new(scale);
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
