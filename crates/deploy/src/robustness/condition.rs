//! A condition as environment settings: the model's own environment with domain
//! randomisation switched on and every range pinned, so that a cell is exactly an evaluation
//! of the model under one fixed condition.

use super::grid::{Condition, Nominal};
use crate::error::{DeployError, Result};
use fairgrasp_env::arm::{ObservationNoise, RandomizationConfig};
use fairgrasp_env::registry;
use fairgrasp_sim::scene::SceneConfig;

/// The nominal object mass and friction of environment `env_id` configured by `base` (its
/// scene's first object). Errors when the environment is not an arm task.
pub fn nominal_of(env_id: &str, base: &toml::Table) -> Result<Nominal> {
    let what = format!("the environment of the model ({env_id})");
    let full = registry::effective_config(env_id, base)?;
    if registry::arm_offer(env_id).is_none() {
        return Err(DeployError::config(
            what,
            format!(
                "is not an arm task (no [randomization] to pin): robustness is measured on \
                 the arm tasks ({})",
                registry::arm_ids().join(", ")
            ),
        ));
    }
    let scene: SceneConfig = match full.get("scene") {
        Some(value) => value
            .clone()
            .try_into()
            .map_err(|e: toml::de::Error| DeployError::config(&what, format!("[scene]: {e}")))?,
        None => SceneConfig::default(),
    };
    let object = scene
        .objects
        .first()
        .ok_or_else(|| DeployError::config(&what, "the scene has no object"))?;
    Ok(Nominal {
        object_mass: object.mass,
        object_friction: object.friction,
    })
}

/// The randomisation section that fixes `condition`: every range degenerate at the nominal
/// value (URDF joint damping, unscaled gains and objects, no jitter) except the condition's
/// own; position noise on the TCP and object groups only.
pub fn pinned_randomization(nominal: &Nominal, condition: &Condition) -> RandomizationConfig {
    let mass = nominal.object_mass * condition.mass_factor;
    let position_noise = condition.noise_mm / 1000.0;
    RandomizationConfig {
        enabled: true,
        object_mass: [mass, mass],
        object_friction: [condition.friction, condition.friction],
        object_scale: [1.0, 1.0],
        joint_damping_scale: Some([1.0, 1.0]),
        actuator_gain_scale: [1.0, 1.0],
        min_latency_steps: condition.latency_steps,
        max_latency_steps: condition.latency_steps,
        initial_joint_jitter: 0.0,
        joint_offset: condition.joint_offset_deg.to_radians(),
        observation_noise: ObservationNoise {
            joint_position: 0.0,
            joint_velocity: 0.0,
            ee_position: position_noise,
            ee_orientation: 0.0,
            ee_velocity: 0.0,
            object_position: position_noise,
            object_orientation: 0.0,
            gripper_opening: 0.0,
        },
        ..RandomizationConfig::default()
    }
}

/// `base` (the model's environment settings) with its randomisation replaced by the one that
/// fixes `condition`; checked by the registry.
pub fn condition_table(
    env_id: &str,
    base: &toml::Table,
    nominal: &Nominal,
    condition: &Condition,
) -> Result<toml::Table> {
    let randomization = pinned_randomization(nominal, condition);
    let value = toml::Value::try_from(&randomization)
        .map_err(|e| DeployError::Other(format!("randomisation settings: {e}")))?;
    let mut table = base.clone();
    table.insert("randomization".into(), value);
    registry::validate(env_id, &table).map_err(|e| {
        DeployError::config(
            format!("the settings for condition {condition:?}"),
            e.to_string(),
        )
    })?;
    Ok(table)
}
