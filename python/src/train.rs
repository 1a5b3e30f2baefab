//! The native trainer and evaluator, driven from Python with the GIL released. The progress
//! callback runs on the calling thread between iterations (the GIL taken back for it); Ctrl-C
//! and a callback returning False stop the run there, after which the final model, logs and
//! summary are written as at a normal end.

use crate::convert::{apply_settings, table_from_dict, to_toml};
use crate::errors::{ConfigError, rl_error};
use fairgrasp_rl::Policy as NativePolicy;
use fairgrasp_rl::configs::builtin_table;
use fairgrasp_rl::train::RunDir;
use fairgrasp_rl::train::{
    HELD_OUT_SEED_BASE, Progress, TrainConfig, evaluate as native_evaluate, resume_until,
    train_until,
};
use pyo3::exceptions::{PyOSError, PyRuntimeError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::ops::ControlFlow;
use std::path::PathBuf;

fn progress_dict<'py>(py: Python<'py>, p: &Progress) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("num_timesteps", p.num_timesteps)?;
    d.set_item("total_timesteps", p.total_timesteps)?;
    d.set_item("fps", p.fps)?;
    d.set_item("ep_rew_mean", p.ep_rew_mean)?;
    d.set_item("rollout_success_rate", p.rollout_success_rate)?;
    d.set_item("eval_count", p.eval_count)?;
    d.set_item("best_success_rate", p.best_success_rate)?;
    if let Some(e) = &p.last_eval {
        let eval = PyDict::new(py);
        eval.set_item("success_rate", e.success_rate)?;
        eval.set_item("mean_return", e.mean_return)?;
        eval.set_item("mean_length", e.mean_length)?;
        eval.set_item("episodes", e.episodes)?;
        for (name, value) in e.final_extras.iter() {
            eval.set_item(name, value)?;
        }
        d.set_item("last_eval", eval)?;
    } else {
        d.set_item("last_eval", py.None())?;
    }
    let extras = PyDict::new(py);
    for (name, value) in p.rollout_max_extras.iter() {
        extras.set_item(name, value)?;
    }
    d.set_item("rollout_max_extras", extras)?;
    Ok(d)
}

fn to_json(value: &impl serde::Serialize) -> PyResult<String> {
    serde_json::to_string(value).map_err(|e| PyRuntimeError::new_err(e.to_string()))
}

/// The starting table: `config` as a dict or a TOML file path, else the built-in settings of
/// `algo` on `env_id`.
fn config_table(
    config: Option<&Bound<'_, PyAny>>,
    env_id: Option<&str>,
    algo: Option<&str>,
) -> PyResult<toml::Table> {
    match config {
        None => builtin_table(
            env_id.unwrap_or(fairgrasp_env::ENV_ID),
            algo.unwrap_or("ppo").parse().map_err(rl_error)?,
        )
        .map_err(rl_error),
        Some(value) => {
            if let Ok(dict) = value.cast::<PyDict>() {
                return table_from_dict(dict);
            }
            let path: PathBuf = value.extract().map_err(|_| {
                ConfigError::new_err(
                    "invalid setting `config`: expected a dict of settings or the path of a TOML file",
                )
            })?;
            let text = std::fs::read_to_string(&path)
                .map_err(|e| PyOSError::new_err(format!("{}: {e}", path.display())))?;
            text.parse().map_err(|e| {
                ConfigError::new_err(format!("{}: not valid TOML: {e}", path.display()))
            })
        }
    }
}

/// Runs `work` with the GIL released, calling `callback` with a progress dict after each
/// iteration; returns the summary as JSON text, or the error that stopped the run (Ctrl-C,
/// an exception in the callback) once the run has written its final model.
fn drive(
    py: Python<'_>,
    callback: Option<Py<PyAny>>,
    work: impl FnOnce(
        &mut dyn FnMut(&Progress) -> ControlFlow<()>,
    ) -> fairgrasp_rl::error::Result<fairgrasp_rl::train::TrainSummary>
    + Send,
) -> PyResult<String> {
    let mut stopped_by: Option<PyErr> = None;
    let result = py.detach(|| {
        let mut on_progress = |p: &Progress| {
            Python::attach(|py| {
                if let Err(e) = py.check_signals() {
                    stopped_by = Some(e);
                    return ControlFlow::Break(());
                }
                let Some(callback) = &callback else {
                    return ControlFlow::Continue(());
                };
                let outcome = progress_dict(py, p).and_then(|d| callback.bind(py).call1((d,)));
                match outcome {
                    Ok(value) if value.is(pyo3::types::PyBool::new(py, false)) => {
                        ControlFlow::Break(())
                    }
                    Ok(_) => ControlFlow::Continue(()),
                    Err(e) => {
                        stopped_by = Some(e);
                        ControlFlow::Break(())
                    }
                }
            })
        };
        work(&mut on_progress)
    });
    let summary = result.map_err(rl_error)?;
    if let Some(e) = stopped_by {
        return Err(e);
    }
    to_json(&summary)
}

/// Trains with the native trainer (what `fairgrasp train` runs) and returns the summary as
/// JSON text. `config`: a dict of the training TOML's keys or a TOML file path (default: the
/// built-in settings of `algo` on `env_id`); `settings`: keys to change (dotted or nested).
/// `resume`: continue the run in `run_dir` from its latest checkpoint instead.
#[pyfunction]
#[pyo3(signature = (config=None, run_dir=None, env_id=None, algo=None, settings=None, callback=None, resume=false))]
#[allow(clippy::too_many_arguments)]
pub fn train(
    py: Python<'_>,
    config: Option<&Bound<'_, PyAny>>,
    run_dir: Option<PathBuf>,
    env_id: Option<&str>,
    algo: Option<&str>,
    settings: Option<&Bound<'_, PyDict>>,
    callback: Option<Py<PyAny>>,
    resume: bool,
) -> PyResult<String> {
    if resume {
        let Some(dir) = run_dir else {
            return Err(ConfigError::new_err(
                "invalid setting `resume`: name the run to continue with run_dir",
            ));
        };
        if config.is_some() || env_id.is_some() || algo.is_some() {
            return Err(ConfigError::new_err(
                "invalid setting `resume`: a resumed run keeps its own config, env_id and algo (change keys with settings)",
            ));
        }
        let mut overrides = Vec::new();
        if let Some(dict) = settings {
            for (key, value) in dict.iter() {
                let key: String = key.extract()?;
                let value = to_toml(&key, &value)?;
                overrides.push(format!("{key}={value}"));
            }
        }
        return drive(py, callback, |on_progress| {
            resume_until(&dir, &overrides, on_progress)
        });
    }
    let mut table = config_table(config, env_id, algo)?;
    if let Some(id) = env_id {
        table.insert("env_id".into(), toml::Value::String(id.into()));
    }
    if let Some(algo) = algo {
        table.insert("algo".into(), toml::Value::String(algo.into()));
    }
    if let Some(dict) = settings {
        apply_settings(&mut table, "", dict)?;
    }
    let config = TrainConfig::from_toml_str(&table.to_string(), &[]).map_err(rl_error)?;
    let run_dir = match run_dir {
        Some(dir) if RunDir::new(&dir).holds_a_run() => {
            return Err(ConfigError::new_err(format!(
                "invalid setting `run_dir`: {} already holds a training run; continue it with resume=True or choose another",
                dir.display()
            )));
        }
        Some(dir) => dir,
        None => RunDir::default_for(config.algo.algo().as_str(), &config.env_id)
            .path()
            .to_path_buf(),
    };
    drive(py, callback, |on_progress| {
        train_until(&config, &run_dir, on_progress)
    })
}

/// A saved model's deterministic success rate, mean return and length over `episodes`
/// episodes seeded `seed, seed+1, …` (what `fairgrasp eval --json` prints), as JSON text.
#[pyfunction]
#[pyo3(signature = (model, episodes=100, seed=HELD_OUT_SEED_BASE, settings=None))]
pub fn evaluate(
    py: Python<'_>,
    model: PathBuf,
    episodes: u32,
    seed: u64,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<String> {
    if episodes == 0 {
        return Err(ConfigError::new_err(
            "invalid setting `episodes`: must be at least 1",
        ));
    }
    let mut policy = py.detach(|| NativePolicy::load(&model)).map_err(rl_error)?;
    let mut table = policy.env_settings(&[]).map_err(rl_error)?;
    if let Some(dict) = settings {
        apply_settings(&mut table, "", dict)?;
    }
    let env_id = policy.env_id().to_string();
    fairgrasp_env::registry::validate(&env_id, &table).map_err(crate::errors::env_error)?;
    let result = py
        .detach(|| {
            native_evaluate(
                &mut |obs, images| policy.act_with_images(obs, images, true),
                &env_id,
                &table,
                episodes,
                seed,
            )
        })
        .map_err(rl_error)?;
    to_json(&result)
}

/// The built-in training configuration of `algo` on `env_id` as TOML text (what `train` starts
/// from without a config).
#[pyfunction]
#[pyo3(signature = (env_id=None, algo=None))]
pub fn default_train_config(env_id: Option<&str>, algo: Option<&str>) -> PyResult<String> {
    let id = env_id.unwrap_or(fairgrasp_env::ENV_ID);
    fairgrasp_env::registry::spec(id).map_err(crate::errors::env_error)?;
    let algo_named = algo.unwrap_or("ppo").parse().map_err(rl_error)?;
    let mut table = builtin_table(id, algo_named).map_err(rl_error)?;
    table.insert("env_id".into(), toml::Value::String(id.into()));
    if let Some(algo) = algo {
        table.insert("algo".into(), toml::Value::String(algo.into()));
    }
    let config = TrainConfig::from_toml_str(&table.to_string(), &[]).map_err(rl_error)?;
    toml::to_string(&config).map_err(|e| PyRuntimeError::new_err(e.to_string()))
}
