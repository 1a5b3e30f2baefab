//! Training through the gripper's controller: `[control.gripper]` moves the simulated fingers
//! as a `MoveGripper` does on the arm — a set point that leaves from where the fingers are when
//! the command changes and moves at the gripper's speed ([`GripperRamp`], the twin's model too)
//! — instead of jumping the fingers' target to open or closed.

use crate::error::{EnvError, Result};
use fairgrasp_sim::SimError;
use fairgrasp_sim::control::{FINGERS_FULL_SPEED_PERCENT_PER_S, GripperRamp};
use fairgrasp_sim::scene::Scene;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// The `[control.gripper]` settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GripperConfig {
    /// Off: the fingers' target jumps to open or closed (the default, and how every model
    /// before this option was trained).
    pub enabled: bool,
    /// The set point's speed (% of the stroke per second, in the policy's time), drawn per
    /// episode from this range. The deployment commands the gripper at the speed scale's
    /// share of full speed, so in the policy's time the set point moves at full speed at every
    /// scale; full speed is the simulated fingers' own (1500 %/s) unless measured otherwise.
    pub speed_percent_per_s: [f32; 2],
}

impl Default for GripperConfig {
    fn default() -> Self {
        let full = FINGERS_FULL_SPEED_PERCENT_PER_S as f32;
        Self {
            enabled: false,
            speed_percent_per_s: [full, full],
        }
    }
}

impl GripperConfig {
    /// Checks the speed range; errors name the key.
    pub fn validate(&self) -> Result<()> {
        let [lo, hi] = self.speed_percent_per_s;
        if !(lo.is_finite() && hi.is_finite() && 0.0 < lo && lo <= hi && hi <= 1e5) {
            return Err(EnvError::config(
                "control.gripper.speed_percent_per_s",
                format!("must be [low, high] with 0 < low <= high <= 100000, got [{lo}, {hi}]"),
            ));
        }
        Ok(())
    }

    /// This episode's gripper, when enabled: at rest at the fingers' present target, its speed
    /// drawn from the range (no draw when the range is one value) and, as the deployment
    /// commands it, times the speed scale in the simulator's time.
    pub fn drive(
        &self,
        scene: &Scene,
        speed_scale: f32,
        rng: &mut impl Rng,
    ) -> Option<GripperDrive> {
        if !self.enabled {
            return None;
        }
        let [lo, hi] = self.speed_percent_per_s.map(f64::from);
        let speed = if lo < hi {
            rng.random_range(lo..hi)
        } else {
            lo
        };
        let max = scene.max_opening() as f64;
        Some(GripperDrive {
            ramp: GripperRamp::at(scene.gripper_target() as f64 / max * 100.0),
            speed: speed * speed_scale as f64,
        })
    }
}

/// One episode's gripper controller.
#[derive(Clone, Debug, PartialEq)]
pub struct GripperDrive {
    ramp: GripperRamp,
    /// % of the stroke per second of simulated time.
    speed: f64,
}

impl GripperDrive {
    /// A command to open or close: a new move from where the fingers are when it changes the
    /// target (the deployment sends `MoveGripper` only then).
    pub fn command(&mut self, scene: &Scene, open: bool) {
        let target = if open { 100.0 } else { 0.0 };
        if self.ramp.target() != target {
            let fingers = (scene.gripper_opening() / scene.max_opening()) as f64 * 100.0;
            self.ramp.command(fingers, target, self.speed);
        }
    }

    /// Moves the set point on by one physics step and sends it to the fingers.
    pub fn drive(&mut self, scene: &mut Scene) -> std::result::Result<(), SimError> {
        let percent = self.ramp.advance(scene.dt() as f64);
        scene.set_gripper_target((percent / 100.0) as f32 * scene.max_opening())
    }
}
