//! The built-in training configurations: the files in `configs/`, compiled in so that `fairgrasp
//! train` and Python's `fairgrasp.train()` start from the same tuned settings in any directory.

use crate::error::{Result, RlError};
use crate::train::Algo;
use std::path::{Path, PathBuf};

pub const PPO_GRASP_TOML: &str = include_str!("../../../configs/ppo_grasp.toml");
pub const SAC_GRASP_TOML: &str = include_str!("../../../configs/sac_grasp.toml");
pub const TD3_GRASP_TOML: &str = include_str!("../../../configs/td3_grasp.toml");
pub const PPO_PICK_PLACE_TOML: &str = include_str!("../../../configs/ppo_pick_place.toml");
pub const PPO_SORT_TOML: &str = include_str!("../../../configs/ppo_sort.toml");

/// The built-in configuration text for an env and algorithm, and whether it was tuned for that
/// env (else it is the algorithm's grasp file, whose `[env]` table is the grasp task's).
pub fn builtin_config(env_id: &str, algo: Algo) -> (&'static str, bool) {
    match (env_id, algo) {
        ("FaArmPickPlace-v0", Algo::Ppo) => (PPO_PICK_PLACE_TOML, true),
        ("FaArmSort-v0", Algo::Ppo) => (PPO_SORT_TOML, true),
        (fairgrasp_env::ENV_ID, Algo::Ppo) => (PPO_GRASP_TOML, true),
        (fairgrasp_env::ENV_ID, Algo::Sac) => (SAC_GRASP_TOML, true),
        (fairgrasp_env::ENV_ID, Algo::Td3) => (TD3_GRASP_TOML, true),
        (_, Algo::Ppo) => (PPO_GRASP_TOML, false),
        (_, Algo::Sac) => (SAC_GRASP_TOML, false),
        (_, Algo::Td3) => (TD3_GRASP_TOML, false),
    }
}

/// The starting table of a run of `algo` on `env_id`: the tuned file where there is one, else
/// the algorithm's grasp settings with the env's own defaults (its `[env]` table dropped).
pub fn builtin_table(env_id: &str, algo: Algo) -> Result<toml::Table> {
    let (text, tuned) = builtin_config(env_id, algo);
    let mut table: toml::Table = text
        .parse()
        .map_err(|e| RlError::Other(format!("a built-in config: {e}")))?;
    if !tuned {
        table.remove("env");
    }
    Ok(table)
}

/// `FaArmPickPlace-v0` → `pick_place`, `Pendulum-v1` → `pendulum`: run directory names.
pub fn short_env_name(env_id: &str) -> String {
    let stem = env_id.split("-v").next().unwrap_or(env_id);
    let stem = stem.strip_prefix("FaArm").unwrap_or(stem);
    let mut out = String::new();
    for (i, c) in stem.chars().enumerate() {
        if c.is_uppercase() && i > 0 {
            out.push('_');
        }
        out.extend(c.to_lowercase());
    }
    out
}

/// `runs/<algo>_<env>` (e.g. `runs/ppo_grasp`), or the first free `runs/<algo>_<env>_<n>`: where
/// a run goes when no directory is named.
pub fn default_run_dir(algo: &str, env_id: &str) -> PathBuf {
    next_free_run_dir(
        Path::new("runs"),
        &format!("{algo}_{}", short_env_name(env_id)),
    )
}

/// Whether `dir` already holds a training run (its config or checkpoints).
pub fn holds_a_run(dir: &Path) -> bool {
    dir.join("config.toml").exists() || dir.join("checkpoints").exists()
}

/// `runs/<name>` (e.g. `ppo_grasp`), or `runs/<name>_<n>` with the first free n (like SB3's
/// `PPO_1`, `PPO_2`, … TensorBoard runs).
pub fn next_free_run_dir(root: &Path, name: &str) -> PathBuf {
    let first = root.join(name);
    if !holds_a_run(&first) {
        return first;
    }
    (2..)
        .map(|n| root.join(format!("{name}_{n}")))
        .find(|dir| !holds_a_run(dir))
        .expect("an unused run directory")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::TrainConfig;

    #[test]
    fn every_builtin_config_parses_and_untuned_ones_take_the_envs_defaults() {
        for id in fairgrasp_env::registry::ids() {
            for algo in Algo::ALL {
                let table = builtin_table(id, algo).unwrap();
                let config = TrainConfig::from_toml_str(
                    &table.to_string(),
                    &[
                        format!("env_id=\"{id}\""),
                        format!("algo=\"{}\"", algo.as_str()),
                    ],
                )
                .unwrap_or_else(|e| panic!("{id}/{algo}: {e}"));
                assert_eq!(config.algo, algo);
                if !builtin_config(id, algo).1 {
                    assert!(
                        config.env.is_empty(),
                        "{id}/{algo} kept the grasp task's [env]"
                    );
                }
            }
        }
    }
}
