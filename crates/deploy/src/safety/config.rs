//! The `[safety]` settings.

use crate::error::{DeployError, Result};
use serde::{Deserialize, Serialize};

/// The highest joint acceleration cap accepted (deg/s²). FAIRINO publishes no acceleration
/// limit for the FR5; this is twice the 720 deg/s² the deployment models are trained through
/// (`[control.servo]`), so the filter never lets set points change speed more than twice as
/// fast as anything a policy has met, and the arm still brakes from full speed within 125 ms.
pub const MAX_JOINT_ACC_DEG_S2: f64 = 1440.0;

/// Limits the safety layer enforces on every servo set point, in the robot's units.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafetyConfig {
    /// Kept inside each joint's soft limits from the calibration file (deg).
    pub joint_margin_deg: f64,
    /// Joint speed cap at `speed_scale` 1 (deg/s); the FR5's joints reach 180 deg/s.
    pub max_joint_speed_deg_s: f64,
    /// Joint acceleration cap at `speed_scale` 1 (deg/s²).
    pub max_joint_acc_deg_s2: f64,
    /// Global speed scale in (0, 1]: starts low, raise it once the arm behaves. It slows the
    /// policy's motion in time, as a teach pendant's speed slider does: the policy runs at its
    /// control period over the scale, speeds are capped at scale × the cap and accelerations
    /// at scale² × the cap, so the arm makes the trained motion, slower.
    pub speed_scale: f64,
    /// The TCP must stay in this box (robot base frame, mm).
    pub workspace_min_mm: [f64; 3],
    /// Upper corner of that box (mm), above `workspace_min_mm` on every axis.
    pub workspace_max_mm: [f64; 3],
    /// Height of the table top in the base frame (mm); the TCP stays `table_margin_mm` above
    /// it. Unset: the height the model was trained with.
    pub table_z_mm: Option<f64>,
    /// How far the TCP stays above the table top (mm), ≥ 0.
    pub table_margin_mm: f64,
    /// Every part of the arm and gripper (the fingertips, 20 mm past the TCP, included) stays
    /// this far above the table (mm). 3 mm keeps a top-down TCP 23 mm up, under the 25 mm the
    /// deployment models are trained to keep it at; the TCP's own margin alone let the
    /// fingertips 10 mm into the table.
    pub arm_clearance_mm: f64,
    /// Every part of the arm stays inside this box (robot base frame, mm): the cell's walls
    /// and ceiling. The default is the FR5's reach with a tool (922 mm from the shoulder):
    /// set your cell's.
    pub cell_min_mm: [f64; 3],
    /// Upper corner of the cell (mm), above `cell_min_mm` on every axis; the TCP's box lies
    /// inside it.
    pub cell_max_mm: [f64; 3],
    /// The newest state may be at most this old (ms); the stream sends one every 8 ms. Frames
    /// whose controller clock has stood still this long are old too.
    pub state_deadline_ms: f64,
    /// The newest object pose may be at most this old (ms); a perception at 30 Hz sends one
    /// every 33 ms.
    pub pose_deadline_ms: f64,
    /// A camera policy's newest images may be at most this old (ms) when it acts; a camera at
    /// 30 Hz sends one every 33 ms.
    pub frame_deadline_ms: f64,
    /// The servo period (ms): one ServoJ per period, the controller's 8 ms.
    pub servo_period_ms: f64,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            joint_margin_deg: 3.0,
            max_joint_speed_deg_s: 180.0,
            max_joint_acc_deg_s2: 720.0,
            speed_scale: 0.25,
            workspace_min_mm: [150.0, -500.0, -50.0],
            workspace_max_mm: [850.0, 500.0, 700.0],
            table_z_mm: None,
            table_margin_mm: 10.0,
            arm_clearance_mm: 3.0,
            cell_min_mm: [-1200.0, -1200.0, -1200.0],
            cell_max_mm: [1200.0, 1200.0, 1400.0],
            state_deadline_ms: 50.0,
            pose_deadline_ms: 250.0,
            frame_deadline_ms: 150.0,
            servo_period_ms: 8.0,
        }
    }
}

impl SafetyConfig {
    /// Checks every value; errors name the key.
    pub fn validate(&self) -> Result<()> {
        let bad = |key: &str, msg: &str| Err(DeployError::config(format!("safety.{key}"), msg));
        let positive = |key: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                bad(key, "must be a positive number")
            }
        };
        if !(self.joint_margin_deg.is_finite() && (0.0..=30.0).contains(&self.joint_margin_deg)) {
            return bad("joint_margin_deg", "must be in [0, 30] degrees");
        }
        positive("max_joint_speed_deg_s", self.max_joint_speed_deg_s)?;
        if self.max_joint_speed_deg_s > 180.0 {
            return bad(
                "max_joint_speed_deg_s",
                "the FR5's joints top out at 180 deg/s",
            );
        }
        positive("max_joint_acc_deg_s2", self.max_joint_acc_deg_s2)?;
        if self.max_joint_acc_deg_s2 > MAX_JOINT_ACC_DEG_S2 {
            return bad(
                "max_joint_acc_deg_s2",
                &format!(
                    "at most {MAX_JOINT_ACC_DEG_S2} deg/s² (twice the 720 the deployment models \
                     train through)"
                ),
            );
        }
        if !(self.speed_scale.is_finite() && self.speed_scale > 0.0 && self.speed_scale <= 1.0) {
            return bad("speed_scale", "must be in (0, 1]");
        }
        for k in 0..3 {
            let (lo, hi) = (self.workspace_min_mm[k], self.workspace_max_mm[k]);
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return bad(
                    "workspace_min_mm",
                    "each minimum must be finite and below its maximum (workspace_max_mm)",
                );
            }
        }
        if let Some(z) = self.table_z_mm
            && !z.is_finite()
        {
            return bad("table_z_mm", "must be finite");
        }
        if !(self.table_margin_mm.is_finite() && self.table_margin_mm >= 0.0) {
            return bad("table_margin_mm", "must be ≥ 0");
        }
        if !(self.arm_clearance_mm.is_finite() && self.arm_clearance_mm >= 0.0) {
            return bad("arm_clearance_mm", "must be ≥ 0");
        }
        for k in 0..3 {
            let (lo, hi) = (self.cell_min_mm[k], self.cell_max_mm[k]);
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return bad(
                    "cell_min_mm",
                    "each minimum must be finite and below its maximum (cell_max_mm)",
                );
            }
            if self.workspace_min_mm[k] < lo || self.workspace_max_mm[k] > hi {
                return bad(
                    "workspace_min_mm",
                    "the TCP's workspace box must lie inside the cell (cell_min_mm, cell_max_mm)",
                );
            }
        }
        positive("state_deadline_ms", self.state_deadline_ms)?;
        positive("pose_deadline_ms", self.pose_deadline_ms)?;
        positive("frame_deadline_ms", self.frame_deadline_ms)?;
        if !(1.0..=16.0).contains(&self.servo_period_ms) {
            return bad(
                "servo_period_ms",
                "ServoJ's cmdT allows 1–16 ms (the controller's 8 ms is usual)",
            );
        }
        Ok(())
    }

    /// The speed cap in force (deg/s).
    pub fn speed_cap(&self) -> f64 {
        self.max_joint_speed_deg_s * self.speed_scale
    }

    /// The acceleration cap in force (deg/s²): time slowed by the scale divides accelerations
    /// by its square.
    pub fn acc_cap(&self) -> f64 {
        self.max_joint_acc_deg_s2 * self.speed_scale * self.speed_scale
    }
}
