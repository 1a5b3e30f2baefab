//! Simulator joints ↔ robot joints: a TOML file of per-joint sign, offset and soft limits.
//!
//! `robot_deg = sign · sim_deg + offset_deg`, and back. The soft limits are in the robot's
//! degrees; the safety layer keeps its margin inside them. Written by `fairgrasp calibrate`,
//! or by hand:
//!
//! ```toml
//! robot = "FR5"
//! [[joint]]
//! sign = 1
//! offset_deg = 0.0
//! min_deg = -175.0
//! max_deg = 175.0
//! # … six [[joint]] tables, j1 to j6
//! [camera]          # a camera policy's scene camera as mounted (robot base frame, m)
//! eye = [1.05, 0.0, 1.45]
//! target = [0.45, 0.0, 0.78]
//! fov_deg = 50.0
//! [wrist_camera]    # its wrist camera as mounted (TCP frame: z the approach, y the fingers' travel)
//! offset = [0.08, 0.0, -0.12]
//! direction = [0.0, 0.0, 1.0]
//! fov_deg = 70.0
//! ```

use crate::error::{DeployError, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

use crate::fairino::fr5;

/// Slack on the published limits (deg): the model's limits are given in radians to 4 places
/// (4.6251 rad is 265.0002 deg).
const PUBLISHED_SLACK_DEG: f64 = 0.01;

/// One joint's mapping.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointCalibration {
    /// +1 when the robot's joint turns the same way as the simulator's, -1 otherwise.
    pub sign: i8,
    /// The robot's reading when the simulator's joint is at 0 (deg).
    pub offset_deg: f64,
    /// Soft limits in the robot's degrees.
    pub min_deg: f64,
    /// Upper soft limit in the robot's degrees, above `min_deg`.
    pub max_deg: f64,
}

/// The cell's scene camera as mounted, in the robot base frame: where a camera policy's images
/// are taken from, compared before a run with the camera the policy learnt with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraPose {
    /// The camera's optical centre (m).
    pub eye: [f64; 3],
    /// A point on its optical axis (m).
    pub target: [f64; 3],
    /// Vertical field of view (deg).
    pub fov_deg: f64,
}

impl CameraPose {
    fn validate(&self) -> Result<()> {
        let finite = self.eye.iter().chain(&self.target).all(|v| v.is_finite());
        if !(finite && length(&self.sight()) > 1e-3) {
            return Err(DeployError::config(
                "calibration camera",
                "eye and target must be finite and apart",
            ));
        }
        check_fov("calibration camera (fov_deg)", self.fov_deg)
    }

    /// The unit viewing direction.
    pub fn direction(&self) -> [f64; 3] {
        unit(&self.sight())
    }

    /// From the eye to the target.
    fn sight(&self) -> [f64; 3] {
        std::array::from_fn(|i| self.target[i] - self.eye[i])
    }
}

/// The cell's wrist camera as mounted, in the TCP frame (z along the approach, y the fingers'
/// travel): compared before a run with the wrist camera the policy learnt with, which looks
/// along the tool's z.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WristCameraMount {
    /// The camera's optical centre (m).
    pub offset: [f64; 3],
    /// Its optical axis (any length but zero).
    pub direction: [f64; 3],
    /// Vertical field of view (deg).
    pub fov_deg: f64,
}

impl WristCameraMount {
    fn validate(&self) -> Result<()> {
        let finite = self
            .offset
            .iter()
            .chain(&self.direction)
            .all(|v| v.is_finite());
        if !(finite && length(&self.direction) > 1e-6) {
            return Err(DeployError::config(
                "calibration wrist_camera",
                "offset and direction must be finite, and direction not zero",
            ));
        }
        check_fov("calibration wrist_camera (fov_deg)", self.fov_deg)
    }

    /// The unit viewing direction.
    pub fn unit_direction(&self) -> [f64; 3] {
        unit(&self.direction)
    }
}

fn length(v: &[f64; 3]) -> f64 {
    v.iter().map(|c| c * c).sum::<f64>().sqrt()
}

fn unit(v: &[f64; 3]) -> [f64; 3] {
    let n = length(v);
    v.map(|c| c / n)
}

fn check_fov(key: &str, fov_deg: f64) -> Result<()> {
    if !(fov_deg.is_finite() && (5.0..=170.0).contains(&fov_deg)) {
        return Err(DeployError::config(
            key,
            format!("must be 5 to 170 degrees, got {fov_deg}"),
        ));
    }
    Ok(())
}

/// The whole arm's mapping.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// A label: the robot model (and serial number, if you like).
    #[serde(default)]
    pub robot: String,
    /// One table per joint, j1 to j6 (`[[joint]]` in the file).
    #[serde(rename = "joint")]
    pub joints: Vec<JointCalibration>,
    /// The scene camera's pose, for camera policies (`[camera]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraPose>,
    /// The wrist camera's mounting, for camera policies that see through one
    /// (`[wrist_camera]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wrist_camera: Option<WristCameraMount>,
}

impl Calibration {
    /// The identity mapping with the simulator's joint limits (rad) as soft limits.
    pub fn identity(limits_rad: &[(f32, f32)]) -> Self {
        Self {
            robot: "FR5".into(),
            joints: limits_rad
                .iter()
                .map(|&(lo, hi)| JointCalibration {
                    sign: 1,
                    offset_deg: 0.0,
                    min_deg: (lo as f64).to_degrees(),
                    max_deg: (hi as f64).to_degrees(),
                })
                .collect(),
            camera: None,
            wrist_camera: None,
        }
    }

    /// Checks the file's values; errors name the joint and the key. The label must name the
    /// FR5 (the arm whose published limits are known), and every soft limit lie within them.
    pub fn validate(&self) -> Result<()> {
        let model = self.robot.split_whitespace().next().unwrap_or("");
        if !model.to_ascii_uppercase().starts_with("FR5") {
            return Err(DeployError::config(
                "calibration robot",
                format!(
                    "\"{}\" is not an FR5: fairgrasp knows the FR5's published joint limits only \
                     (label the file \"FR5 …\")",
                    self.robot
                ),
            ));
        }
        if let Some(camera) = &self.camera {
            camera.validate()?;
        }
        if let Some(wrist) = &self.wrist_camera {
            wrist.validate()?;
        }
        if self.joints.len() != 6 {
            return Err(DeployError::config(
                "calibration",
                format!("6 [[joint]] tables expected, found {}", self.joints.len()),
            ));
        }
        for (i, j) in self.joints.iter().enumerate() {
            let at = |key: &str| format!("calibration joint {} ({key})", i + 1);
            if j.sign != 1 && j.sign != -1 {
                return Err(DeployError::config(at("sign"), "must be 1 or -1"));
            }
            if !(j.offset_deg.is_finite() && j.offset_deg.abs() <= 360.0) {
                return Err(DeployError::config(at("offset_deg"), "must be within ±360"));
            }
            if !(j.min_deg.is_finite() && j.max_deg.is_finite() && j.min_deg < j.max_deg) {
                return Err(DeployError::config(
                    at("min_deg"),
                    format!(
                        "[{}, {}] is not a range: min_deg must be below max_deg",
                        j.min_deg, j.max_deg
                    ),
                ));
            }
            let (lo, hi) = fr5::JOINT_LIMITS_DEG[i];
            if j.min_deg < lo - PUBLISHED_SLACK_DEG || j.max_deg > hi + PUBLISHED_SLACK_DEG {
                return Err(DeployError::config(
                    at("min_deg"),
                    format!(
                        "[{}, {}] deg reaches beyond the FR5's joint {} limits [{lo}, {hi}] deg",
                        j.min_deg,
                        j.max_deg,
                        i + 1
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Reads and checks a calibration file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| {
            DeployError::config(path.display().to_string(), format!("cannot read: {e}"))
        })?;
        let calibration: Self = toml::from_str(&text)
            .map_err(|e| DeployError::config(path.display().to_string(), e.to_string()))?;
        calibration
            .validate()
            .map_err(|e| DeployError::config(path.display().to_string(), e.to_string()))?;
        Ok(calibration)
    }

    /// Writes the file atomically (a temporary file beside it, then a rename).
    pub fn save(&self, path: &Path) -> Result<()> {
        self.validate()?;
        let text = format!(
            "# fairgrasp calibration: robot_deg = sign * sim_deg + offset_deg, soft limits in \
             robot degrees.\n{}",
            toml::to_string(self).map_err(|e| DeployError::Other(e.to_string()))?
        );
        fairgrasp_env::atomic::write(path, text.as_bytes()).map_err(|e| {
            DeployError::config(path.display().to_string(), format!("cannot write: {e}"))
        })
    }

    /// Robot joint angles (deg) for simulator joint angles (rad).
    pub fn to_robot(&self, sim_rad: &[f32]) -> [f64; 6] {
        let mut out = [0.0; 6];
        for (i, j) in self.joints.iter().enumerate().take(6) {
            out[i] = j.sign as f64 * (sim_rad[i] as f64).to_degrees() + j.offset_deg;
        }
        out
    }

    /// Simulator joint angles (rad) for robot joint angles (deg).
    pub fn to_sim(&self, robot_deg: &[f64; 6]) -> Vec<f32> {
        (self.to_sim_deg(robot_deg).iter())
            .map(|d| d.to_radians() as f32)
            .collect()
    }

    /// Simulator joint angles in degrees for robot joint angles (deg).
    pub fn to_sim_deg(&self, robot_deg: &[f64; 6]) -> Vec<f64> {
        self.joints
            .iter()
            .zip(robot_deg)
            .map(|(j, &d)| (d - j.offset_deg) / j.sign as f64)
            .collect()
    }

    /// Joint speeds: robot deg/s → simulator deg/s.
    pub fn speeds_to_sim_deg(&self, robot_deg_s: &[f64; 6]) -> Vec<f64> {
        self.joints
            .iter()
            .zip(robot_deg_s)
            .map(|(j, &d)| d / j.sign as f64)
            .collect()
    }

    /// Each joint's (min, max) soft limits (robot deg).
    pub fn soft_limits(&self) -> Vec<(f64, f64)> {
        self.joints.iter().map(|j| (j.min_deg, j.max_deg)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fr5() -> Calibration {
        let limits: Vec<(f32, f32)> = fr5::JOINT_LIMITS_DEG
            .iter()
            .map(|&(lo, hi)| ((lo as f32).to_radians(), (hi as f32).to_radians()))
            .collect();
        Calibration::identity(&limits)
    }

    #[test]
    fn soft_limits_beyond_the_fr5_s_published_limits_are_refused() {
        assert!(fr5().validate().is_ok());
        // Within ±360, once accepted: joint 3 of the FR5 stops at ±162 deg.
        let mut c = fr5();
        c.joints[2].max_deg = 300.0;
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("joint 3") && e.contains("162"), "{e}");
        let mut c = fr5();
        c.joints[1].min_deg = -300.0;
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("joint 2") && e.contains("-265"), "{e}");
    }

    #[test]
    fn a_calibration_for_another_arm_is_refused() {
        let mut c = fr5();
        c.robot = "FR10 #42".into();
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("FR10") && e.contains("FR5"), "{e}");
        c.robot = "FR5 #1234".into();
        assert!(c.validate().is_ok());
    }

    /// Both camera tables survive a save and a load; an unknown key in them is refused by name.
    #[test]
    fn the_cameras_tables_are_written_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("calibration.toml");
        let mut c = fr5();
        c.camera = Some(CameraPose {
            eye: [1.05, 0.0, 1.45],
            target: [0.45, 0.0, 0.78],
            fov_deg: 50.0,
        });
        c.wrist_camera = Some(WristCameraMount {
            offset: [0.08, 0.0, -0.12],
            direction: [0.0, 0.0, 1.0],
            fov_deg: 70.0,
        });
        c.save(&path).unwrap();
        assert_eq!(Calibration::load(&path).unwrap(), c);
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::write(
            &path,
            text.replace("[wrist_camera]", "[wrist_camera]\ntilt = 3.0"),
        )
        .unwrap();
        let e = Calibration::load(&path).unwrap_err().to_string();
        assert!(e.contains("tilt"), "{e}");
    }
}
