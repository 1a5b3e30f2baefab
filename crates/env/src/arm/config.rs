//! The configuration every arm task shares — scene, control, randomisation, object shapes —
//! around the task's own `[task]` and `[reward]` sections.

pub use crate::arm::shapes::{ShapeKind, ShapesConfig};
use crate::config::{check_non_negative, check_range};
use crate::error::{EnvError, Result};
use serde::{Deserialize, Serialize};
use std::fmt::Debug;

/// Standard deviations of the Gaussian noise added to each observation group, every step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObservationNoise {
    /// rad
    pub joint_position: f32,
    /// rad/s
    pub joint_velocity: f32,
    /// m
    pub ee_position: f32,
    /// rad (Euler angles) or unitless (rotation-matrix entries)
    pub ee_orientation: f32,
    /// m/s
    pub ee_velocity: f32,
    /// m
    pub object_position: f32,
    /// unitless (quaternion / rotation features)
    pub object_orientation: f32,
    /// m
    pub gripper_opening: f32,
}

impl Default for ObservationNoise {
    fn default() -> Self {
        Self {
            joint_position: 0.002,
            joint_velocity: 0.02,
            ee_position: 0.002,
            ee_orientation: 0.01,
            ee_velocity: 0.01,
            object_position: 0.005,
            object_orientation: 0.02,
            gripper_opening: 0.001,
        }
    }
}

/// Domain randomisation. Ranges are sampled uniformly at every reset; noise every step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RandomizationConfig {
    /// Master switch.
    pub enabled: bool,
    /// kg, every object.
    pub object_mass: [f32; 2],
    /// Friction coefficient of every object, within [0, 5].
    pub object_friction: [f32; 2],
    /// Factor on every dimension of each object's shape (a 5 cm cube with [0.9, 1.1] has
    /// edges of 4.5–5.5 cm).
    pub object_scale: [f32; 2],
    /// Viscous damping of each arm joint (N·m·s/rad).
    pub joint_damping: [f32; 2],
    /// When set, each arm joint's damping is its robot description's value times a factor
    /// drawn from this range, instead of a value drawn from `joint_damping` (`[1.0, 1.0]` pins
    /// the nominal damping).
    pub joint_damping_scale: Option<[f32; 2]>,
    /// Factor on the arm's PD gains.
    pub actuator_gain_scale: [f32; 2],
    /// When set, each episode's contact stiffness is `scene.physics.contact_frequency` times a
    /// factor drawn log-uniformly from this range (contacts with the table twice as stiff, as
    /// always): below 1 the pads sink into a squeezed object, as a compliant pad or a softer
    /// engine lets them.
    pub contact_stiffness_scale: Option<[f32; 2]>,
    /// Actions reach the robot `min_latency_steps…max_latency_steps` control steps late (drawn
    /// per episode).
    pub min_latency_steps: u32,
    /// Largest action latency (control steps), at most 10.
    pub max_latency_steps: u32,
    /// Uniform offset added to each home joint angle (± rad).
    pub initial_joint_jitter: f32,
    /// Joint calibration error (± rad, drawn uniformly per joint per episode): the encoders
    /// report `q + e` and the controller servoes the reported angles to its targets. See
    /// [`crate::arm::ArmEnv`] for what the model includes.
    pub joint_offset: f32,
    /// Noise added to each observation group every step.
    pub observation_noise: ObservationNoise,
}

impl Default for RandomizationConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            object_mass: [0.05, 0.2],
            object_friction: [0.5, 1.5],
            object_scale: [0.9, 1.1],
            joint_damping: [0.1, 1.0],
            joint_damping_scale: None,
            actuator_gain_scale: [0.8, 1.2],
            contact_stiffness_scale: None,
            min_latency_steps: 0,
            max_latency_steps: 2,
            initial_joint_jitter: 0.05,
            joint_offset: 0.0,
            observation_noise: ObservationNoise::default(),
        }
    }
}

impl RandomizationConfig {
    /// Checks every range; errors name the key (`randomization.…`).
    pub fn validate(&self) -> Result<()> {
        check_range("randomization.object_mass", self.object_mass, 0.001, 5.0)?;
        check_range(
            "randomization.object_friction",
            self.object_friction,
            0.0,
            5.0,
        )?;
        check_range("randomization.object_scale", self.object_scale, 0.2, 2.0)?;
        check_range(
            "randomization.joint_damping",
            self.joint_damping,
            0.0,
            100.0,
        )?;
        if let Some(scale) = self.joint_damping_scale {
            check_range("randomization.joint_damping_scale", scale, 0.0, 100.0)?;
        }
        check_range(
            "randomization.actuator_gain_scale",
            self.actuator_gain_scale,
            0.05,
            20.0,
        )?;
        if let Some(scale) = self.contact_stiffness_scale {
            check_range("randomization.contact_stiffness_scale", scale, 0.01, 10.0)?;
        }
        if self.max_latency_steps > 10 {
            return Err(EnvError::config(
                "randomization.max_latency_steps",
                "must be at most 10",
            ));
        }
        if self.min_latency_steps > self.max_latency_steps {
            return Err(EnvError::config(
                "randomization.min_latency_steps",
                format!(
                    "must be at most randomization.max_latency_steps ({})",
                    self.max_latency_steps
                ),
            ));
        }
        check_non_negative(
            "randomization.initial_joint_jitter",
            self.initial_joint_jitter,
        )?;
        check_non_negative("randomization.joint_offset", self.joint_offset)?;
        // 0.1 rad (5.7°) is a gross miscalibration, not a calibration error.
        if self.joint_offset > 0.1 {
            return Err(EnvError::config(
                "randomization.joint_offset",
                format!("must be at most 0.1 rad, got {}", self.joint_offset),
            ));
        }
        let n = &self.observation_noise;
        for (key, v) in [
            ("joint_position", n.joint_position),
            ("joint_velocity", n.joint_velocity),
            ("ee_position", n.ee_position),
            ("ee_orientation", n.ee_orientation),
            ("ee_velocity", n.ee_velocity),
            ("object_position", n.object_position),
            ("object_orientation", n.object_orientation),
            ("gripper_opening", n.gripper_opening),
        ] {
            check_non_negative(&format!("randomization.observation_noise.{key}"), v)?;
        }
        Ok(())
    }
}
