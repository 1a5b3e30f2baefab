//! Every knob of the grasp environment, loadable from TOML and overridable by dotted keys.
//!
//! Unknown keys and out-of-range values are errors that name the key.

use crate::core::RenderMode;
use crate::error::{EnvError, Result};
use fairgrasp_sim::scene::SceneConfig;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Which observation vector the environment returns.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObservationPreset {
    /// The design's 23 values: joint angles (6), EE position (3), EE Euler angles (3), object
    /// position (3), object quaternion (4), EE linear velocity (3), gripper opening (1).
    Seed23,
    /// 40 values chosen for learning: continuous orientations, velocities, the EE→object
    /// vector, contact flags and the previous action (see [`crate::observation`]).
    Rich,
}

/// What an action commands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionMode {
    /// Six joint-angle deltas (rad) and a gripper command.
    Joint,
    /// TCP deltas (dx, dy, dz in m, dyaw in rad) with the tool pointing down, and a gripper
    /// command; joint targets come from inverse kinematics.
    Cartesian,
}

/// Which reward the environment pays.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RewardKind {
    /// `success` on success, else 0.
    Sparse,
    /// The design's mix: approach progress, near bonus, one-time grasp and lift-hold bonuses,
    /// time penalty.
    Hybrid,
    /// Dense and staged like ManiSkill's PickCube, shifted to be ≤ 0 so that finishing early
    /// always pays: `(reach + grasped + lift) / 3 − 1` per step, with reach = 1 − tanh(4·d),
    /// grasped ∈ {0, 1}, lift = min(lift / (min_lift + 1 cm), 1) while grasped.
    /// Knocking the object off the table costs the worst reward for every remaining step, so
    /// it never pays to end an episode that way.
    Staged,
}

/// The task: observations, actions, episode limits, success rule.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TaskConfig {
    pub observation: ObservationPreset,
    pub action_mode: ActionMode,
    /// Largest joint-angle change per control step (rad). The design used 0.1 and recommends
    /// 0.05 for smoother motion.
    pub max_joint_delta: f32,
    /// Largest TCP translation per control step in Cartesian mode (m).
    pub max_tcp_delta: f32,
    /// Largest TCP yaw change per control step in Cartesian mode (rad).
    pub max_yaw_delta: f32,
    /// Control steps before the episode is truncated.
    pub max_episode_steps: u32,
    /// Lift above the resting height that counts as lifted (m).
    pub success_min_lift: f32,
    /// Largest object–TCP distance that counts as centred (m).
    pub success_max_offset: f32,
    /// Consecutive control steps the success conditions must hold.
    pub success_hold_steps: u32,
    pub render_mode: Option<RenderMode>,
}

impl Default for TaskConfig {
    fn default() -> Self {
        Self {
            observation: ObservationPreset::Rich,
            action_mode: ActionMode::Joint,
            max_joint_delta: 0.05,
            max_tcp_delta: 0.02,
            max_yaw_delta: 0.1,
            max_episode_steps: 100,
            success_min_lift: 0.05,
            success_max_offset: 0.08,
            success_hold_steps: 10,
            render_mode: None,
        }
    }
}

/// Reward weights. Every term is reported separately in `info.reward_terms`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RewardConfig {
    pub kind: RewardKind,
    /// × (previous EE–object distance − current), per step.
    pub approach: f32,
    /// Paid every step the EE is within `near_radius` of the object.
    pub near: f32,
    pub near_radius: f32,
    /// Paid once per episode, the first time the object is grasped.
    pub grasp: f32,
    /// Paid once per episode, on success (lifted and held).
    pub lift_hold: f32,
    /// Subtracted every step.
    pub time_penalty: f32,
    /// Subtracted when the object leaves the table (the episode terminates).
    pub off_table_penalty: f32,
    /// Sparse reward on success.
    pub success: f32,
}

impl Default for RewardConfig {
    fn default() -> Self {
        Self {
            kind: RewardKind::Hybrid,
            approach: 0.1,
            near: 0.5,
            near_radius: 0.10,
            grasp: 5.0,
            lift_hold: 10.0,
            time_penalty: 0.01,
            off_table_penalty: 10.0,
            success: 10.0,
        }
    }
}

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
    /// kg
    pub object_mass: [f32; 2],
    pub object_friction: [f32; 2],
    /// Cube edge length (m).
    pub object_size: [f32; 2],
    /// Viscous damping of each arm joint (N·m·s/rad).
    pub joint_damping: [f32; 2],
    /// Factor on the arm's PD gains.
    pub actuator_gain_scale: [f32; 2],
    /// Actions reach the robot 0…N control steps late (N drawn per episode).
    pub max_latency_steps: u32,
    /// Uniform offset added to each home joint angle (± rad).
    pub initial_joint_jitter: f32,
    pub observation_noise: ObservationNoise,
}

impl Default for RandomizationConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            object_mass: [0.05, 0.2],
            object_friction: [0.5, 1.5],
            object_size: [0.045, 0.055],
            joint_damping: [0.1, 1.0],
            actuator_gain_scale: [0.8, 1.2],
            max_latency_steps: 2,
            initial_joint_jitter: 0.05,
            observation_noise: ObservationNoise::default(),
        }
    }
}

/// Everything that defines a grasp environment.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EnvConfig {
    pub scene: SceneConfig,
    pub task: TaskConfig,
    pub reward: RewardConfig,
    pub randomization: RandomizationConfig,
}

fn check_range(key: &str, r: [f32; 2], min: f32, max: f32) -> Result<()> {
    if !(r[0].is_finite() && r[1].is_finite() && r[0] <= r[1] && r[0] >= min && r[1] <= max) {
        return Err(EnvError::config(
            key,
            format!("must be [low, high] with {min} <= low <= high <= {max}, got {r:?}"),
        ));
    }
    Ok(())
}

fn check_positive(key: &str, v: f32) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(EnvError::config(
            key,
            format!("must be a positive number, got {v}"),
        ))
    }
}

fn check_non_negative(key: &str, v: f32) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(EnvError::config(
            key,
            format!("must be a non-negative number, got {v}"),
        ))
    }
}

impl EnvConfig {
    /// Checks every range; the error names the key.
    pub fn validate(&self) -> Result<()> {
        self.scene.validate().map_err(|e| match e {
            fairgrasp_sim::SimError::Config { key, problem } => {
                EnvError::config(format!("scene.{key}"), problem)
            }
            other => EnvError::Sim(other),
        })?;
        let t = &self.task;
        check_positive("task.max_joint_delta", t.max_joint_delta)?;
        if t.max_joint_delta > 0.5 {
            return Err(EnvError::config(
                "task.max_joint_delta",
                format!(
                    "{} rad per step is unsafe; use at most 0.5",
                    t.max_joint_delta
                ),
            ));
        }
        check_positive("task.max_tcp_delta", t.max_tcp_delta)?;
        if t.max_tcp_delta > 0.1 {
            return Err(EnvError::config(
                "task.max_tcp_delta",
                "use at most 0.1 m per step",
            ));
        }
        check_positive("task.max_yaw_delta", t.max_yaw_delta)?;
        if t.max_episode_steps == 0 {
            return Err(EnvError::config(
                "task.max_episode_steps",
                "must be at least 1",
            ));
        }
        check_positive("task.success_min_lift", t.success_min_lift)?;
        check_positive("task.success_max_offset", t.success_max_offset)?;
        if t.success_hold_steps == 0 {
            return Err(EnvError::config(
                "task.success_hold_steps",
                "must be at least 1",
            ));
        }
        let r = &self.reward;
        for (key, v) in [
            ("reward.approach", r.approach),
            ("reward.near", r.near),
            ("reward.grasp", r.grasp),
            ("reward.lift_hold", r.lift_hold),
            ("reward.time_penalty", r.time_penalty),
            ("reward.off_table_penalty", r.off_table_penalty),
            ("reward.success", r.success),
        ] {
            check_non_negative(key, v)?;
        }
        check_positive("reward.near_radius", r.near_radius)?;
        let d = &self.randomization;
        check_range("randomization.object_mass", d.object_mass, 0.001, 5.0)?;
        check_range("randomization.object_friction", d.object_friction, 0.0, 5.0)?;
        check_range("randomization.object_size", d.object_size, 0.01, 0.085)?;
        check_range("randomization.joint_damping", d.joint_damping, 0.0, 100.0)?;
        check_range(
            "randomization.actuator_gain_scale",
            d.actuator_gain_scale,
            0.05,
            20.0,
        )?;
        if d.max_latency_steps > 10 {
            return Err(EnvError::config(
                "randomization.max_latency_steps",
                "must be at most 10",
            ));
        }
        check_non_negative("randomization.initial_joint_jitter", d.initial_joint_jitter)?;
        let n = &d.observation_noise;
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

    /// Parses TOML text, applies `overrides` (`dotted.key=value`, value in TOML syntax, e.g.
    /// `task.action_mode="cartesian"` or `randomization.enabled=true`), then validates.
    pub fn from_toml_str(text: &str, overrides: &[String]) -> Result<Self> {
        let mut table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| EnvError::config("(file)", e.to_string()))?;
        for item in overrides {
            apply_override(&mut table, item)?;
        }
        // Deserialise from text so errors quote the offending line (and so name the key).
        let text =
            toml::to_string(&table).map_err(|e| EnvError::config("(overrides)", e.to_string()))?;
        let config: EnvConfig =
            toml::from_str(&text).map_err(|e| EnvError::config("config", e.to_string()))?;
        config.validate()?;
        Ok(config)
    }

    /// Loads a TOML file (see [`Self::from_toml_str`]).
    pub fn load(path: &Path, overrides: &[String]) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| EnvError::File {
            path: path.display().to_string(),
            problem: e.to_string(),
        })?;
        Self::from_toml_str(&text, overrides).map_err(|e| match e {
            EnvError::Config { key, problem } => EnvError::File {
                path: path.display().to_string(),
                problem: format!("invalid setting `{key}`: {problem}"),
            },
            other => other,
        })
    }

    /// The defaults with `overrides` applied.
    pub fn with_overrides(overrides: &[String]) -> Result<Self> {
        Self::from_toml_str("", overrides)
    }

    /// The configuration as TOML text (e.g. to save it beside a run).
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# could not serialise: {e}\n"))
    }
}

/// Sets `section.key=value` in a TOML table (value in TOML syntax; bare words become strings),
/// creating sections as needed. Shared by every configuration that takes `--set` overrides.
pub fn apply_override(table: &mut toml::Table, item: &str) -> Result<()> {
    let (key, value) = item
        .split_once('=')
        .ok_or_else(|| EnvError::config(item, "an override must look like `section.key=value`"))?;
    let key = key.trim();
    let value_text = value.trim();
    // Parse the value as TOML; bare words become strings (`task.action_mode=cartesian`).
    let value: toml::Value = format!("v = {value_text}")
        .parse::<toml::Table>()
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(value_text.to_string()));
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(EnvError::config(key, "empty key segment"));
    }
    let mut current = table;
    for part in &parts[..parts.len() - 1] {
        let entry = current
            .entry(part.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        current = entry
            .as_table_mut()
            .ok_or_else(|| EnvError::config(key, format!("`{part}` is a value, not a section")))?;
    }
    current.insert(parts[parts.len() - 1].to_string(), value);
    Ok(())
}
