//! Training through the deployment's motion model: `[control.servo]` streams each control
//! step's joint targets through a [`JointRamp`] (in `fairgrasp_sim::control`), a set point every
//! servo period, as the deployment's safety filter does on the real arm, so a policy meets on
//! the robot the motion it learnt on.

use crate::arm::drives::ArmDrives;
use fairgrasp_sim::SimError;
pub use fairgrasp_sim::control::JointRamp;
use fairgrasp_sim::scene::Scene;
use serde::{Deserialize, Serialize};

/// The `[control.servo]` settings: train through the deployment's motion model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ServoConfig {
    /// Off: each control step's joint targets go straight to the simulated drives (the
    /// default, and how every model before this option was trained).
    pub enabled: bool,
    /// Set-point period (ms); the FAIRINO controller's ServoJ period is 8 ms.
    pub period_ms: f32,
    /// Joint speed cap (deg/s); the FR5's joints reach 180 deg/s.
    pub max_joint_speed_deg_s: f32,
    /// Joint acceleration cap (deg/s²).
    pub max_joint_acc_deg_s2: f32,
}

impl Default for ServoConfig {
    fn default() -> Self {
        // The deployment's safety defaults at speed scale 1 (`[safety]`, docs/deployment.md).
        Self {
            enabled: false,
            period_ms: 8.0,
            max_joint_speed_deg_s: 180.0,
            max_joint_acc_deg_s2: 720.0,
        }
    }
}

impl ServoConfig {
    /// A ramp for `scene`'s arm started at its present targets, when enabled: a set point every
    /// servo period of the control step, the caps in radians. At `speed_scale` s the control
    /// step lasts its period over s and the caps are the deployment's: speed × s, acceleration
    /// × s² (the same motion in the policy's time).
    pub fn ramp(&self, scene: &Scene, speed_scale: f32) -> Option<JointRamp> {
        if !self.enabled {
            return None;
        }
        let period = scene.control_period() / speed_scale;
        let ticks = servo_ticks(period, self.period_ms);
        let limits: Vec<(f64, f64)> = (scene.arm_limits().iter())
            .map(|&(lo, hi)| (lo as f64, hi as f64))
            .collect();
        let s = speed_scale as f64;
        let mut ramp = JointRamp::new(
            &limits,
            (self.max_joint_speed_deg_s as f64).to_radians() * s,
            (self.max_joint_acc_deg_s2 as f64).to_radians() * s * s,
            period as f64 / ticks as f64,
        );
        let start: Vec<f64> = scene.arm_targets().iter().map(|&v| v as f64).collect();
        ramp.start(&start);
        Some(ramp)
    }
}

/// Servo periods per control step: the control period over the servo period, rounded (the
/// FAIRINO's 8 ms into 33.3 ms: 4).
pub fn servo_ticks(control_period: f32, period_ms: f32) -> u32 {
    ((control_period * 1000.0 / period_ms).round() as u32).max(1)
}

/// One control step of `substeps` physics steps through the servo ramp: a set point every
/// servo period, each held by the joints for that period's share of the substeps, or taken
/// by the arm's `drives` when given. `before_substep` may drive the scene before each physics
/// substep; `after_substep` sees it after, with the count done.
pub(crate) fn step_servoed(
    scene: &mut Scene,
    ramp: &mut JointRamp,
    mut drives: Option<&mut ArmDrives>,
    substeps: u32,
    target: &[f32],
    mut before_substep: impl FnMut(&mut Scene) -> std::result::Result<(), SimError>,
    mut after_substep: impl FnMut(&Scene, u32),
) -> std::result::Result<(), SimError> {
    let period = scene.dt() * substeps as f32;
    let servo_period = ramp.caps().2;
    let ticks = servo_ticks(period, servo_period as f32 * 1000.0)
        .min(substeps)
        .max(1);
    let target: Vec<f64> = target.iter().map(|&v| v as f64).collect();
    let mut done = 0;
    for k in 1..=ticks {
        let set_point = ramp.next(&target).expect("the ramp starts at reset");
        match drives.as_deref_mut() {
            Some(d) => d.command(&set_point, servo_period),
            None => {
                let q: Vec<f32> = set_point.iter().map(|&v| v as f32).collect();
                scene.set_arm_targets(&q)?;
            }
        }
        // Spread the substeps over the ticks (8 over 4: two each).
        let until = substeps * k / ticks;
        while done < until {
            if let Some(d) = drives.as_deref_mut() {
                d.drive(scene)?;
            }
            before_substep(scene)?;
            scene.step_physics()?;
            done += 1;
            after_substep(scene, done);
        }
    }
    scene.check_finite()
}
