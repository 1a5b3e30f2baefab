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
//! ```

use crate::error::{DeployError, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

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
    pub max_deg: f64,
}

/// The whole arm's mapping.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// A label: the robot model (and serial number, if you like).
    #[serde(default)]
    pub robot: String,
    #[serde(rename = "joint")]
    pub joints: Vec<JointCalibration>,
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
        }
    }

    /// Checks the file's values; errors name the joint and the key.
    pub fn validate(&self) -> Result<()> {
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
            if j.min_deg < -360.0 || j.max_deg > 360.0 {
                return Err(DeployError::config(
                    at("min_deg"),
                    "limits must be within ±360",
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
        crate::atomic::write(path, text.as_bytes())
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
