//! Forward kinematics in the robot's units, for the safety layer's workspace box.

use crate::calibration::Calibration;
use crate::safety::ForwardKinematics;
use fairgrasp_sim::kinematics::SerialChain;

/// The TCP position (mm, robot base frame) for robot joint angles (deg): the calibration maps
/// them to the simulator's joints, whose chain (base to TCP) gives the pose.
pub fn tcp_forward_kinematics(chain: SerialChain, calibration: Calibration) -> ForwardKinematics {
    Box::new(move |robot_deg: &[f64; 6]| {
        let q: Vec<f64> = calibration
            .to_sim(robot_deg)
            .into_iter()
            .map(f64::from)
            .collect();
        let p = chain.forward(&q).translation.vector * 1000.0;
        p.iter().all(|v| v.is_finite()).then(|| [p.x, p.y, p.z])
    })
}
