//! Which built-in training configuration a run starts from (the files in `configs/`, compiled
//! in as [`crate::algo::BUILTIN_CONFIGS`]), so that `fairgrasp train` and Python's
//! `fairgrasp.train()` start from the same tuned settings in any directory.

use crate::algo::{Algo, BUILTIN_CONFIGS};
use crate::error::{Result, RlError};

/// The built-in configuration text for an env and algorithm, and whether it was tuned for that
/// env (else it is the algorithm's grasp file, whose `[env]` table is the grasp task's).
pub fn builtin_config(env_id: &str, algo: Algo) -> (&'static str, bool) {
    let named = |name: String| {
        BUILTIN_CONFIGS
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, text)| *text)
    };
    match named(format!("{algo}_{}", short_env_name(env_id))) {
        Some(text) => (text, true),
        None => match named(format!("{algo}_grasp")) {
            Some(text) => (text, false),
            None => unreachable!("no built-in {algo}_grasp config (a test checks every algorithm)"),
        },
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
                assert_eq!(config.algo.algo(), algo);
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
