//! The identified drive model as a TOML file: what `fairgrasp sysid` writes and what the twin
//! (`fairgrasp twin --drives FILE`) reads.
//!
//! ```toml
//! env = "FaArmGrasp-v0"
//!
//! [[joints]]
//! joint = 1
//! delay_ms = 8.1
//! tau_ms = 15.2
//! rms_residual_deg = 0.004
//! samples = 812
//!
//! [gripper]
//! speed_percent = 50
//! close_time_s = 1.62
//! final_position_percent = 0.0
//! stalled = false
//! ```
//!
//! The delay and lag are what the arm adds to the training simulator's own PD joints, between
//! the controller's set point and the joint; joints not listed were not identified.

use super::fit::{MAX_DELAY_MS, MAX_TAU_MS};
use crate::error::{DeployError, Result};
use crate::twin::faults::{JointTracking, TrackingModel};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One joint's identified drive.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointDrive {
    /// 1…6.
    pub joint: usize,
    /// Pure delay (ms).
    pub delay_ms: f64,
    /// First-order lag time constant (ms).
    pub tau_ms: f64,
    /// RMS of what the simulator with this drive leaves unexplained (deg).
    pub rms_residual_deg: f64,
    /// Joint readings the fit used.
    pub samples: usize,
}

/// The gripper closing on nothing.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GripperTiming {
    /// The MoveGripper speed used (%).
    pub speed_percent: u8,
    /// From the command to the reported position at its end (s).
    pub close_time_s: f64,
    /// Where it stopped (% of the stroke; 0 is closed).
    pub final_position_percent: f64,
    /// It stopped short of closed with nothing between the fingers.
    pub stalled: bool,
}

/// The file.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DriveModel {
    /// The environment whose simulated arm the drives were fitted against.
    pub env: String,
    /// The identified joints (`[[joints]]`), each at most once; joints not listed were not
    /// identified.
    #[serde(default)]
    pub joints: Vec<JointDrive>,
    /// The gripper's closing time, when it was measured (`[gripper]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gripper: Option<GripperTiming>,
}

impl DriveModel {
    /// Checks every value; errors name the joint and the key.
    pub fn validate(&self) -> Result<()> {
        let mut seen = [false; 6];
        for j in &self.joints {
            let what = format!("joint {}", j.joint);
            if !(1..=6).contains(&j.joint) {
                return Err(DeployError::config(what, "joints are numbered 1 to 6"));
            }
            if std::mem::replace(&mut seen[j.joint - 1], true) {
                return Err(DeployError::config(what, "listed twice"));
            }
            let in_range = |v: f64, max: f64| v.is_finite() && (0.0..=max).contains(&v);
            if !in_range(j.delay_ms, MAX_DELAY_MS) {
                return Err(DeployError::config(
                    what,
                    format!("delay_ms {} is outside 0…{MAX_DELAY_MS}", j.delay_ms),
                ));
            }
            if !in_range(j.tau_ms, MAX_TAU_MS) {
                return Err(DeployError::config(
                    what,
                    format!("tau_ms {} is outside 0…{MAX_TAU_MS}", j.tau_ms),
                ));
            }
        }
        if let Some(g) = &self.gripper
            && !(g.close_time_s.is_finite() && g.close_time_s >= 0.0)
        {
            return Err(DeployError::config(
                "gripper",
                format!("close_time_s {} is not a time", g.close_time_s),
            ));
        }
        Ok(())
    }

    /// The twin's drive tracking: the identified joints' delay and lag, the others none.
    pub fn tracking(&self) -> TrackingModel {
        let mut model = TrackingModel::default();
        for j in &self.joints {
            if (1..=6).contains(&j.joint) {
                model[j.joint - 1] = JointTracking {
                    delay_ms: j.delay_ms,
                    tau_ms: j.tau_ms,
                };
            }
        }
        model
    }

    /// The file's text: a comment line, then the TOML.
    pub fn to_toml(&self) -> Result<String> {
        Ok(format!(
            "# fairgrasp sysid: per joint, the delay and first-order lag between the \
             controller's set point and the joint that the simulator's own PD joints lack.\n{}",
            toml::to_string(self).map_err(|e| DeployError::Other(e.to_string()))?
        ))
    }

    /// Parses and checks a file's text.
    pub fn from_toml(text: &str) -> Result<Self> {
        let model: Self =
            toml::from_str(text).map_err(|e| DeployError::config("drive model", e.to_string()))?;
        model.validate()?;
        Ok(model)
    }

    /// Reads and checks a file; errors name it.
    pub fn load(path: &Path) -> Result<Self> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path)
            .map_err(|e| DeployError::config(&name, format!("cannot read: {e}")))?;
        Self::from_toml(&text).map_err(|e| DeployError::config(name, e.to_string()))
    }

    /// Writes a new file atomically; an existing file is never replaced (an error says so).
    pub fn save_new(&self, path: &Path) -> Result<()> {
        self.validate()?;
        fairgrasp_env::atomic::write_new(path, self.to_toml()?.as_bytes()).map_err(|e| {
            let message = if e.kind() == std::io::ErrorKind::AlreadyExists {
                "exists already; it is kept (give another path, or move it away)".to_string()
            } else {
                format!("cannot write: {e}")
            };
            DeployError::config(path.display().to_string(), message)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> DriveModel {
        DriveModel {
            env: "FaArmGrasp-v0".into(),
            joints: vec![
                JointDrive {
                    joint: 2,
                    delay_ms: 12.0,
                    tau_ms: 30.0,
                    rms_residual_deg: 0.01,
                    samples: 700,
                },
                JointDrive {
                    joint: 5,
                    delay_ms: 4.0,
                    tau_ms: 50.0,
                    rms_residual_deg: 0.01,
                    samples: 700,
                },
            ],
            gripper: Some(GripperTiming {
                speed_percent: 50,
                close_time_s: 1.5,
                final_position_percent: 0.0,
                stalled: false,
            }),
        }
    }

    #[test]
    fn round_trips_and_maps_to_the_twins_tracking() {
        let m = model();
        let back = DriveModel::from_toml(&m.to_toml().unwrap()).unwrap();
        assert_eq!(back, m);
        let t = m.tracking();
        assert_eq!((t[1].delay_ms, t[1].tau_ms), (12.0, 30.0));
        assert_eq!((t[4].delay_ms, t[4].tau_ms), (4.0, 50.0));
        assert_eq!(t[0], JointTracking::default());
    }

    #[test]
    fn bad_files_are_named() {
        let mut m = model();
        m.joints[1].joint = 7;
        assert!(m.validate().unwrap_err().to_string().contains("joint 7"));
        let mut m = model();
        m.joints[1].joint = 2;
        assert!(m.validate().unwrap_err().to_string().contains("twice"));
        let mut m = model();
        m.joints[0].tau_ms = f64::NAN;
        assert!(m.validate().unwrap_err().to_string().contains("tau_ms"));
        let e = DriveModel::from_toml("env = 3").unwrap_err().to_string();
        assert!(e.contains("drive model"), "{e}");
        let e = DriveModel::from_toml("env = \"x\"\nnonsense = 1").unwrap_err();
        assert!(e.to_string().contains("nonsense"), "{e}");
    }

    #[test]
    fn save_never_replaces_a_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sysid.toml");
        model().save_new(&path).unwrap();
        assert_eq!(DriveModel::load(&path).unwrap(), model());
        let e = model().save_new(&path).unwrap_err().to_string();
        assert!(e.contains("exists already"), "{e}");
    }
}
