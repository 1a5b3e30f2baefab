//! Forward kinematics in the robot's units, for the safety layer: the TCP for the workspace
//! box, and every part of the arm and gripper for the table and the cell's walls.

use crate::calibration::Calibration;
use fairgrasp_sim::envelope::Envelope;

/// A part of the arm placed outside what a check allows: its name and where it is (mm, robot
/// base frame).
#[derive(Clone, Debug, PartialEq)]
pub struct PartOutside {
    /// `TCP`, or the model's name of the part (a link, a finger).
    pub part: String,
    /// The TCP, or the centre of the part's covering sphere that was refused (mm, robot base
    /// frame).
    pub at_mm: [f64; 3],
}

/// The arm's forward kinematics for robot joint angles (deg): the calibration maps them to the
/// simulator's joints, whose chain (base to TCP) and envelope give the poses.
#[derive(Clone, Debug)]
pub struct ArmKinematics {
    envelope: Envelope,
    calibration: Calibration,
}

impl ArmKinematics {
    /// The kinematics of `envelope` (the simulator's arm), robot joints mapped through
    /// `calibration`.
    pub fn new(envelope: Envelope, calibration: Calibration) -> Self {
        Self {
            envelope,
            calibration,
        }
    }

    fn sim_rad(&self, robot_deg: &[f64; 6]) -> Vec<f64> {
        (self.calibration.to_sim_deg(robot_deg).into_iter())
            .map(f64::to_radians)
            .collect()
    }

    /// The TCP position (mm, robot base frame), or `None` when it cannot be computed.
    pub fn tcp_mm(&self, robot_deg: &[f64; 6]) -> Option<[f64; 3]> {
        let p = self
            .envelope
            .chain()
            .forward(&self.sim_rad(robot_deg))
            .translation
            .vector
            * 1000.0;
        p.iter().all(|v| v.is_finite()).then(|| [p.x, p.y, p.z])
    }

    /// The first part of the arm whose covering sphere `allowed` refuses (centre in mm, radius
    /// in mm), or `None` when every part is allowed. Non-finite joints refuse the first part.
    pub fn first_part_outside(
        &self,
        robot_deg: &[f64; 6],
        mut allowed: impl FnMut(&[f64; 3], f64) -> bool,
    ) -> Option<PartOutside> {
        let q = self.sim_rad(robot_deg);
        self.envelope
            .first_outside(&q, |c, r| {
                let mm = [c.x * 1000.0, c.y * 1000.0, c.z * 1000.0];
                mm.iter().all(|v| v.is_finite()) && allowed(&mm, r * 1000.0)
            })
            .map(|(part, c)| PartOutside {
                part: part.to_string(),
                at_mm: [c.x * 1000.0, c.y * 1000.0, c.z * 1000.0],
            })
    }
}
