//! The registry of environment ids (Gymnasium's `gymnasium.make`): every environment the
//! project ships, built from its id and a configuration table.
//!
//! A configuration is the env's own TOML table (for the arm tasks: `[scene]`, `[control]`,
//! `[task]`, `[reward]`, `[randomization]`, `[shapes]`, `[render]`); keys it does not know are
//! errors that name them. The training driver, evaluation, saved models and the Python module all go
//! through [`make`], so a new task is usable everywhere once it is listed here. What an arm
//! task offers beyond training ([`ArmOffer`]: a world for the twin, a model side for the
//! deployment loop) is declared here too, so the deployment layer never names a task.

use crate::arm::erased::{nominal_env_of, world_of};
use crate::arm::{ArmEnv, ArmEnvConfig, ArmTaskEnv, ArmWorld, Task};
use crate::config::from_table;
use crate::core::Env;
use crate::error::{EnvError, Result};
use crate::tasks::classic::{Pendulum, PointReach};
use crate::tasks::{grasp::Grasp, pick_place::PickPlace, sort::Sort};

/// One registered environment.
pub struct EnvSpec {
    /// The id [`make`] knows it by, e.g. `FaArmGrasp-v0`.
    pub id: &'static str,
    /// One line on what the env is.
    pub summary: &'static str,
    /// Builds the env from a configuration table (validated).
    pub make: fn(&toml::Table) -> Result<Box<dyn Env>>,
    /// The validated configuration with every key filled in, as TOML text in the order of
    /// the env's settings (`fairgrasp env config`; cheap: no scene is built).
    pub config_toml: fn(&toml::Table) -> Result<String>,
    /// What an arm task offers outside training; `None` for envs without the arm.
    pub arm: Option<ArmOffer>,
}

/// Builds an arm task's world from its configuration table.
pub type WorldFn = fn(&toml::Table) -> Result<Box<dyn ArmWorld>>;
/// Builds an arm task's nominal env from its configuration table.
pub type DeploymentFn = fn(&toml::Table) -> Result<Box<dyn ArmTaskEnv>>;

/// What an arm task offers outside training.
pub struct ArmOffer {
    /// Its nominal scene staged as a world, judged by the task (the twin).
    pub world: WorldFn,
    /// Its nominal env, which a trained model's deployment reads the model's observation,
    /// action mapping and success rule from; `None` while the task cannot be deployed.
    pub deployment: Option<DeploymentFn>,
}

impl ArmOffer {
    const fn of<T: Task>(deployable: bool) -> Self {
        Self {
            world: world_of::<T>,
            deployment: if deployable {
                Some(nominal_env_of::<T>)
            } else {
                None
            },
        }
    }
}

fn make_arm<T: Task>(table: &toml::Table) -> Result<Box<dyn Env>> {
    let config: ArmEnvConfig<T::Settings, T::Reward> = from_table(table.clone())?;
    Ok(Box::new(ArmEnv::<T>::new(config)?))
}

fn config_toml_arm<T: Task>(table: &toml::Table) -> Result<String> {
    let config: ArmEnvConfig<T::Settings, T::Reward> = from_table(table.clone())?;
    config.validate()?;
    toml::to_string(&config).map_err(|e| EnvError::config("config", e.to_string()))
}

fn no_settings(id: &str, table: &toml::Table) -> Result<()> {
    match table.keys().next() {
        None => Ok(()),
        Some(key) => Err(EnvError::config(
            key.clone(),
            format!("{id} has no settings"),
        )),
    }
}

static SPECS: &[EnvSpec] = &[
    EnvSpec {
        id: "FaArmGrasp-v0",
        summary: "lift an object off the table and hold it (one cube by default; random shapes with `shapes.enabled`)",
        make: make_arm::<Grasp>,
        config_toml: config_toml_arm::<Grasp>,
        arm: Some(ArmOffer::of::<Grasp>(true)),
    },
    EnvSpec {
        id: "FaArmPickPlace-v0",
        summary: "pick the object and bring it to a random goal on the table or up to 20 cm above it",
        make: make_arm::<PickPlace>,
        config_toml: config_toml_arm::<PickPlace>,
        // Its goal has no source on a real cell yet.
        arm: Some(ArmOffer::of::<PickPlace>(false)),
    },
    EnvSpec {
        id: "FaArmSort-v0",
        summary: "put each object into the bin of its colour (3 objects and 2 bins by default)",
        make: make_arm::<Sort>,
        config_toml: config_toml_arm::<Sort>,
        // Its bins have no source on a real cell yet, and its success needs the simulator.
        arm: Some(ArmOffer::of::<Sort>(false)),
    },
    EnvSpec {
        id: "Pendulum-v1",
        summary: "Gymnasium's pendulum swing-up (classic control)",
        make: |t| {
            no_settings("Pendulum-v1", t)?;
            Ok(Box::new(Pendulum::new()))
        },
        config_toml: |t| no_settings("Pendulum-v1", t).map(|_| String::new()),
        arm: None,
    },
    EnvSpec {
        id: "PointReach-v0",
        summary: "push a 2-D point mass to a random goal (classic control)",
        make: |t| {
            no_settings("PointReach-v0", t)?;
            Ok(Box::new(PointReach::new()))
        },
        config_toml: |t| no_settings("PointReach-v0", t).map(|_| String::new()),
        arm: None,
    },
];

/// Every registered environment, in a fixed order.
pub fn specs() -> &'static [EnvSpec] {
    SPECS
}

/// The ids of every registered environment.
pub fn ids() -> Vec<&'static str> {
    SPECS.iter().map(|s| s.id).collect()
}

/// The spec of `id`; the error lists the known ids.
pub fn spec(id: &str) -> Result<&'static EnvSpec> {
    SPECS.iter().find(|s| s.id == id).ok_or_else(|| {
        EnvError::config(
            "env_id",
            format!(
                "unknown environment `{id}`; registered: {}",
                ids().join(", ")
            ),
        )
    })
}

/// The ids of the arm tasks (those with an [`ArmOffer`]).
pub fn arm_ids() -> Vec<&'static str> {
    SPECS
        .iter()
        .filter(|s| s.arm.is_some())
        .map(|s| s.id)
        .collect()
}

/// The ids of the arm tasks whose trained models can be deployed.
pub fn deployable_ids() -> Vec<&'static str> {
    SPECS
        .iter()
        .filter(|s| s.arm.as_ref().is_some_and(|a| a.deployment.is_some()))
        .map(|s| s.id)
        .collect()
}

/// What arm task `id` offers outside training; `None` when `id` is not an arm task (or not
/// registered).
pub fn arm_offer(id: &str) -> Option<&'static ArmOffer> {
    SPECS
        .iter()
        .find(|s| s.id == id)
        .and_then(|s| s.arm.as_ref())
}

/// Builds environment `id` from its configuration table (Gymnasium's `make`).
pub fn make(id: &str, config: &toml::Table) -> Result<Box<dyn Env>> {
    (spec(id)?.make)(config)
}

/// The configuration of `id` with every key at its default.
pub fn default_config(id: &str) -> Result<toml::Table> {
    effective_config(id, &toml::Table::new())
}

/// Checks a configuration of `id` (unknown keys, ranges) without building the env.
pub fn validate(id: &str, config: &toml::Table) -> Result<()> {
    config_toml(id, config).map(|_| ())
}

/// `config` validated and completed with the defaults of every key it leaves out, as TOML
/// text.
pub fn config_toml(id: &str, config: &toml::Table) -> Result<String> {
    (spec(id)?.config_toml)(config)
}

/// `config` validated and completed with the defaults of every key it leaves out.
pub fn effective_config(id: &str, config: &toml::Table) -> Result<toml::Table> {
    config_toml(id, config)?
        .parse()
        .map_err(|e: toml::de::Error| EnvError::config("config", e.to_string()))
}
