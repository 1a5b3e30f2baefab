//! Training through the arm's drives: `[control.drives]` puts a pure delay and a first-order
//! lag per joint between the servo set points and the simulated joints — what `fairgrasp sysid`
//! identifies on the arm (what the simulator's own PD joints lack) and what the twin's
//! `tracking` fault injects, through the same filter ([`DriveFilter`]). As on the controller,
//! each set point is interpolated from the last over its servo period before the drives take it.

use crate::error::{EnvError, Result};
use fairgrasp_sim::SimError;
use fairgrasp_sim::control::{DriveFilter, DriveIntegral, JointTracking};
use fairgrasp_sim::scene::Scene;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// The joints a drive model covers: the FR5's six.
pub const DRIVEN_JOINTS: usize = 6;

/// The `[control.drives]` settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DrivesConfig {
    /// Off: the servo set points go straight to the simulated joints (the default, and how
    /// every model before this option was trained). Needs `[control.servo]`.
    pub enabled: bool,
    /// Each joint's pure delay (ms), j1 first (`fairgrasp train --drives sysid.toml` fills
    /// these from the file).
    pub delay_ms: [f64; DRIVEN_JOINTS],
    /// Each joint's first-order lag (ms).
    pub tau_ms: [f64; DRIVEN_JOINTS],
    /// Every delay and lag of an episode is the nominal times one factor drawn from this
    /// range (no draw for one value): the identified model is a nominal, not the arm.
    pub scale: [f64; 2],
    /// The drives' integral action (the twin's, [`DriveIntegral`]): a joint held off its set
    /// point, on the table or an object, is pushed harder the longer it is held, up to 0.5°
    /// more. On by default: the controller's drives do it and the twin models it.
    pub integral: bool,
}

impl Default for DrivesConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            delay_ms: [0.0; DRIVEN_JOINTS],
            tau_ms: [0.0; DRIVEN_JOINTS],
            scale: [1.0, 1.0],
            integral: true,
        }
    }
}

impl DrivesConfig {
    /// Checks the settings when enabled (`servo_enabled`: whether `[control.servo]` is on);
    /// errors name the key (`control.drives.…`).
    pub fn validate(&self, servo_enabled: bool) -> Result<()> {
        if !self.enabled {
            return Ok(());
        }
        if !servo_enabled {
            return Err(EnvError::config(
                "control.drives.enabled",
                "the drives follow the servo set points: enable [control.servo] too",
            ));
        }
        for (key, values) in [("delay_ms", &self.delay_ms), ("tau_ms", &self.tau_ms)] {
            if let Some(j) = (0..DRIVEN_JOINTS).find(|&j| !(0.0..=500.0).contains(&values[j])) {
                return Err(EnvError::config(
                    format!("control.drives.{key}"),
                    format!("joint {} is {} ms, outside 0…500 ms", j + 1, values[j]),
                ));
            }
        }
        let [lo, hi] = self.scale;
        if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo <= hi && hi <= 10.0) {
            return Err(EnvError::config(
                "control.drives.scale",
                format!("must be [low, high] with 0 <= low <= high <= 10, got [{lo}, {hi}]"),
            ));
        }
        Ok(())
    }

    /// This episode's drives, when enabled: at rest at the arm's present targets, the model's
    /// scale drawn from the range (no draw when it is one value), returned with the drives.
    pub fn drives(&self, scene: &Scene, rng: &mut impl Rng) -> Result<Option<(ArmDrives, f64)>> {
        if !self.enabled {
            return Ok(None);
        }
        let targets = scene.arm_targets();
        let start: [f64; DRIVEN_JOINTS] = (targets.iter().map(|&v| v as f64))
            .collect::<Vec<_>>()
            .try_into()
            .map_err(|_| {
                EnvError::config(
                    "control.drives",
                    format!(
                        "a drive model covers {DRIVEN_JOINTS} joints; this arm has {}",
                        targets.len()
                    ),
                )
            })?;
        let [lo, hi] = self.scale;
        let scale = if lo < hi {
            rng.random_range(lo..hi)
        } else {
            lo
        };
        let model = std::array::from_fn(|j| JointTracking {
            delay_ms: self.delay_ms[j] * scale,
            tau_ms: self.tau_ms[j] * scale,
        });
        let drives = ArmDrives {
            filter: DriveFilter::new(start, 0.0),
            model,
            time: 0.0,
            set_point: start,
            set_at: 0.0,
            integral: self.integral.then(DriveIntegral::new),
        };
        Ok(Some((drives, scale)))
    }
}

/// One episode's drives, on their own clock (s of simulated time).
#[derive(Clone, Debug)]
pub struct ArmDrives {
    filter: DriveFilter<DRIVEN_JOINTS>,
    model: [JointTracking; DRIVEN_JOINTS],
    time: f64,
    set_point: [f64; DRIVEN_JOINTS],
    /// When the set point is reached (s): its servo period after it was sent.
    set_at: f64,
    integral: Option<DriveIntegral<DRIVEN_JOINTS>>,
}

impl ArmDrives {
    /// A new servo set point (rad), reached `period` (s) from now.
    pub fn command(&mut self, set_point: &[f64], period: f64) {
        for (s, v) in self.set_point.iter_mut().zip(set_point) {
            *s = *v;
        }
        self.set_at = self.time + period;
    }

    /// The drives' output for the coming physics step to the joints' targets; the clock moves
    /// on by the step.
    pub fn drive(&mut self, scene: &mut Scene) -> std::result::Result<(), SimError> {
        let dt = scene.dt() as f64;
        let q = (self.filter).follow(&self.model, self.set_at, self.set_point, self.time);
        self.time += dt;
        let Some(integral) = self.integral.as_mut() else {
            return scene.set_arm_targets(&q.map(|v| v as f32));
        };
        // The last step ended where the joints are now: learn from it, then drive this one.
        integral.learn(&scene.arm_positions(), dt);
        scene.set_arm_targets(&integral.drive(q).map(|v| v as f32))
    }
}
