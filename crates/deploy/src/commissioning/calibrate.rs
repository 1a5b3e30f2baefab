//! A calibration from two readings of the robot taken by the operator: at the model's home pose,
//! and after jogging every joint about +10° in the simulator's positive direction.

use crate::calibration::{Calibration, JointCalibration};
use crate::error::{DeployError, Result};
use crate::fairino::fr5;

/// Smallest jog (deg) that tells a joint's direction apart from backlash and reading noise.
const MIN_JOG_DEG: f64 = 3.0;

/// The two readings (robot degrees).
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationReadings {
    /// The simulator's home pose (deg), as the operator was asked to set it.
    pub home_sim_deg: [f64; 6],
    /// The robot's reading at that pose.
    pub at_home: [f64; 6],
    /// The robot's reading after each joint was jogged in the simulator's positive direction.
    pub after_jog: [f64; 6],
}

/// Sign from the jog's direction, offset from the home reading, soft limits from the
/// simulator's joint limits (rad) mapped through both.
pub fn calibration_from_readings(
    readings: &CalibrationReadings,
    sim_limits_rad: &[(f32, f32)],
    robot: &str,
) -> Result<Calibration> {
    if sim_limits_rad.len() != 6 {
        return Err(DeployError::config(
            "calibration",
            format!("6 joints expected, the model has {}", sim_limits_rad.len()),
        ));
    }
    let mut joints = Vec::with_capacity(6);
    for (i, &(lo, hi)) in sim_limits_rad.iter().enumerate() {
        let jog = readings.after_jog[i] - readings.at_home[i];
        if !jog.is_finite() || jog.abs() < MIN_JOG_DEG {
            return Err(DeployError::config(
                format!("joint {}", i + 1),
                format!(
                    "moved {jog:.2} deg between the readings; jog it about +10 deg (at least \
                     {MIN_JOG_DEG}) in the simulator's positive direction"
                ),
            ));
        }
        let sign: i8 = if jog > 0.0 { 1 } else { -1 };
        let offset_deg = readings.at_home[i] - sign as f64 * readings.home_sim_deg[i];
        let a = sign as f64 * (lo as f64).to_degrees() + offset_deg;
        let b = sign as f64 * (hi as f64).to_degrees() + offset_deg;
        // Never beyond the arm's own limits, whatever the offset.
        let (published_lo, published_hi) = fr5::JOINT_LIMITS_DEG[i];
        joints.push(JointCalibration {
            sign,
            offset_deg,
            min_deg: a.min(b).max(published_lo),
            max_deg: a.max(b).min(published_hi),
        });
    }
    let calibration = Calibration {
        robot: robot.to_string(),
        joints,
        camera: None,
        wrist_camera: None,
    };
    calibration.validate()?;
    Ok(calibration)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signs_offsets_and_limits_come_from_the_readings() {
        let limits = vec![(-3.0f32, 3.0f32); 6];
        let home = [0.0, -90.0, 90.0, -90.0, -90.0, 0.0];
        // A robot whose joint 2 turns the other way and whose joint 6 reads 1.5 deg high.
        let truth = |sim: [f64; 6]| {
            let mut r = sim;
            r[1] = -sim[1];
            r[5] = sim[5] + 1.5;
            r
        };
        let mut jogged = home;
        for v in &mut jogged {
            *v += 10.0;
        }
        let readings = CalibrationReadings {
            home_sim_deg: home,
            at_home: truth(home),
            after_jog: truth(jogged),
        };
        let c = calibration_from_readings(&readings, &limits, "FR5 test").unwrap();
        assert_eq!(c.joints[1].sign, -1);
        assert_eq!(c.joints[0].sign, 1);
        assert!((c.joints[5].offset_deg - 1.5).abs() < 1e-9);
        assert!(c.joints[1].offset_deg.abs() < 1e-9);
        // The mapping reproduces the robot's readings.
        let sim_rad: Vec<f32> = jogged.iter().map(|d| d.to_radians() as f32).collect();
        let r = c.to_robot(&sim_rad);
        let want = truth(jogged);
        for i in 0..6 {
            assert!(
                (r[i] - want[i]).abs() < 1e-4,
                "joint {i}: {} vs {}",
                r[i],
                want[i]
            );
        }
        // Soft limits: the simulator's (±171.9 deg here) through the mapping, cut to the FR5's
        // published limits (joint 2 tops out at 85 deg).
        let max = 3.0f64.to_degrees();
        assert!(
            (c.joints[0].min_deg + max).abs() < 1e-4 && (c.joints[0].max_deg - max).abs() < 1e-4
        );
        assert!((c.joints[1].min_deg + max).abs() < 1e-4 && c.joints[1].max_deg == 85.0);
        // An offset never carries a soft limit past the published one.
        let shifted = CalibrationReadings {
            at_home: readings.at_home.map(|v| v + 30.0),
            after_jog: readings.after_jog.map(|v| v + 30.0),
            ..readings
        };
        let c = calibration_from_readings(&shifted, &limits, "FR5 test").unwrap();
        for (i, j) in c.joints.iter().enumerate() {
            let (lo, hi) = fr5::JOINT_LIMITS_DEG[i];
            assert!(j.min_deg >= lo && j.max_deg <= hi, "joint {i}: {j:?}");
        }
    }

    #[test]
    fn a_joint_that_did_not_move_is_named() {
        let readings = CalibrationReadings {
            home_sim_deg: [0.0; 6],
            at_home: [0.0; 6],
            after_jog: [10.0, 10.0, 1.0, 10.0, 10.0, 10.0],
        };
        let e = calibration_from_readings(&readings, &[(-3.0, 3.0); 6], "x").unwrap_err();
        assert!(e.to_string().contains("joint 3"), "{e}");
    }
}
