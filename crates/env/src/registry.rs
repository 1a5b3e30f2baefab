//! The registry of environment ids (Gymnasium's `gymnasium.make`): every environment the
//! project ships, built from its id and a configuration table.
//!
//! A configuration is the env's own TOML table (for the arm tasks: `[scene]`, `[control]`,
//! `[task]`, `[reward]`, `[randomization]`, `[shapes]`, `[render]`); keys it does not know are
//! errors that name them. The training driver, evaluation, saved models and the Python module all go
//! through [`make`], so a new task is usable everywhere once it is listed here.

use crate::arm::{ArmEnv, ArmEnvConfig, Task};
use crate::config::from_table;
use crate::core::Env;
use crate::error::{EnvError, Result};
use crate::tasks::classic::{Pendulum, PointReach};
use crate::tasks::{grasp::Grasp, pick_place::PickPlace, sort::Sort};

/// One registered environment.
pub struct EnvSpec {
    pub id: &'static str,
    /// One line on what the env is.
    pub summary: &'static str,
    /// Builds the env from a configuration table (validated).
    pub make: fn(&toml::Table) -> Result<Box<dyn Env>>,
    /// The validated configuration with every key filled in, as TOML text in the order of
    /// the env's settings (`fairgrasp env config`; cheap: no scene is built).
    pub config_toml: fn(&toml::Table) -> Result<String>,
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
    },
    EnvSpec {
        id: "FaArmPickPlace-v0",
        summary: "pick the object and bring it to a random goal on the table or up to 20 cm above it",
        make: make_arm::<PickPlace>,
        config_toml: config_toml_arm::<PickPlace>,
    },
    EnvSpec {
        id: "FaArmSort-v0",
        summary: "put each object into the bin of its colour (3 objects and 2 bins by default)",
        make: make_arm::<Sort>,
        config_toml: config_toml_arm::<Sort>,
    },
    EnvSpec {
        id: "Pendulum-v1",
        summary: "Gymnasium's pendulum swing-up (classic control)",
        make: |t| {
            no_settings("Pendulum-v1", t)?;
            Ok(Box::new(Pendulum::new()))
        },
        config_toml: |t| no_settings("Pendulum-v1", t).map(|_| String::new()),
    },
    EnvSpec {
        id: "PointReach-v0",
        summary: "push a 2-D point mass to a random goal (classic control)",
        make: |t| {
            no_settings("PointReach-v0", t)?;
            Ok(Box::new(PointReach::new()))
        },
        config_toml: |t| no_settings("PointReach-v0", t).map(|_| String::new()),
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
