//! One registered environment (Gymnasium's `Env`), built through the registry from a settings
//! dict whose keys are the env's TOML keys. The Python class `fairgrasp.FairgraspEnv` wraps it.

use crate::convert::{
    Bounds, bounds, f32_values, frame_object, info_dict, insert_path, metadata_dict, obs_info,
    observation, render_mode_name, table_from_dict,
};
use crate::errors::{ConfigError, env_error, poisoned, with_open};
use fairgrasp_env::spaces::{BoxSpace, ImageSpace};
use fairgrasp_env::{Env as _, RescaleAction, registry};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use std::sync::Mutex;

/// What the Python classes build an env from: the id, the settings table (render and
/// observation modes included) and whether actions are rescaled to [-1, 1].
pub struct EnvRecipe {
    pub id: String,
    pub table: toml::Table,
    pub rescale_action: bool,
}

impl EnvRecipe {
    pub fn new(
        id: &str,
        config: Option<&Bound<'_, PyDict>>,
        rescale_action: bool,
        render_mode: Option<&str>,
        obs_mode: Option<&str>,
    ) -> PyResult<Self> {
        registry::spec(id).map_err(env_error)?;
        let mut table = match config {
            Some(dict) => table_from_dict(dict)?,
            None => toml::Table::new(),
        };
        let defaults = registry::default_config(id).map_err(env_error)?;
        let modes = [
            (
                render_mode,
                "render_mode",
                "task",
                "task.render_mode",
                "render modes",
            ),
            (
                obs_mode,
                "obs_mode",
                "camera",
                "camera.mode",
                "observation modes",
            ),
        ];
        for (mode, argument, section, key, what) in modes {
            let Some(mode) = mode else { continue };
            if !defaults.contains_key(section) {
                return Err(ConfigError::new_err(format!(
                    "invalid setting `{argument}`: {id} has no {what}"
                )));
            }
            let value = toml::Value::String(mode.to_string());
            insert_path(&mut table, key, value, argument)?;
        }
        registry::validate(id, &table).map_err(env_error)?;
        Ok(Self {
            id: id.to_string(),
            table,
            rescale_action,
        })
    }

    /// A fresh env; with `rescale_action`, behind [`RescaleAction`] (the trainer's setting).
    pub fn build(&self) -> fairgrasp_env::Result<Box<dyn fairgrasp_env::Env>> {
        let env = registry::make(&self.id, &self.table)?;
        Ok(if self.rescale_action {
            Box::new(RescaleAction::new(env)?)
        } else {
            env
        })
    }
}

/// One environment. `reset`, `step` and `render` release the GIL while the simulator runs.
#[pyclass(module = "fairgrasp._native", name = "Env")]
pub struct Env {
    inner: Mutex<Option<Box<dyn fairgrasp_env::Env>>>,
    id: String,
    table: toml::Table,
    rescale_action: bool,
    observation_space: BoxSpace,
    image_space: Option<ImageSpace>,
    action_space: BoxSpace,
}

/// `(name, height, width, channels)` of each camera image.
pub fn image_views(space: Option<&ImageSpace>) -> Vec<(String, u32, u32, u32)> {
    let views = space.map(|s| s.views.as_slice()).unwrap_or_default();
    (views.iter())
        .map(|v| (v.name.clone(), v.height, v.width, v.channels))
        .collect()
}

impl Env {
    /// The observation as Python sees it (a dict with camera images).
    fn observation<'py>(
        &self,
        py: Python<'py>,
        obs: Vec<f32>,
        image: Option<Vec<u8>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let images = self.image_space.as_ref().zip(image.as_deref());
        observation(py, obs, images)
    }

    fn with_env<T: Send>(
        &self,
        py: Python<'_>,
        f: impl FnOnce(&mut Box<dyn fairgrasp_env::Env>) -> fairgrasp_env::Result<T> + Send,
    ) -> PyResult<T> {
        with_open(py, &self.inner, "env", f)
    }
}

#[pymethods]
impl Env {
    /// Builds env `env_id` from `config` (the env's TOML keys as a dict: nested dicts for
    /// sections, or dotted keys). With `rescale_action` the action space is [-1, 1] and mapped
    /// linearly onto the env's own bounds (what `fairgrasp train` learns in).
    #[new]
    #[pyo3(signature = (env_id, config=None, rescale_action=true, render_mode=None, obs_mode=None))]
    fn new(
        py: Python<'_>,
        env_id: &str,
        config: Option<&Bound<'_, PyDict>>,
        rescale_action: bool,
        render_mode: Option<&str>,
        obs_mode: Option<&str>,
    ) -> PyResult<Self> {
        let recipe = EnvRecipe::new(env_id, config, rescale_action, render_mode, obs_mode)?;
        let env = py.detach(|| recipe.build()).map_err(env_error)?;
        Ok(Self {
            observation_space: env.observation_space().clone(),
            image_space: env.image_space().cloned(),
            action_space: env.action_space().clone(),
            inner: Mutex::new(Some(env)),
            id: recipe.id,
            table: recipe.table,
            rescale_action,
        })
    }

    /// Starts an episode: `(observation, info)`. A seed restarts the env's random stream.
    #[pyo3(signature = (seed=None))]
    fn reset<'py>(&self, py: Python<'py>, seed: Option<u64>) -> PyResult<Bound<'py, PyTuple>> {
        let (obs, info, image) = self.with_env(py, |env| {
            let (obs, info) = env.reset(seed)?;
            Ok((obs, info, env.image().map(<[u8]>::to_vec)))
        })?;
        obs_info(py, self.observation(py, obs, image)?, &info)
    }

    /// One control period: `(observation, reward, terminated, truncated, info)`. Actions
    /// outside the space are clipped; a wrong shape, NaN or infinity raises `ActionError`.
    fn step<'py>(
        &self,
        py: Python<'py>,
        action: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let action = f32_values(action, "action", &[self.action_space.dim()])?;
        let (step, image) = self.with_env(py, move |env| {
            let step = env.step(&action)?;
            Ok((step, env.image().map(<[u8]>::to_vec)))
        })?;
        PyTuple::new(
            py,
            [
                self.observation(py, step.obs, image)?,
                step.reward.into_pyobject(py)?.into_any(),
                pyo3::types::PyBool::new(py, step.terminated)
                    .to_owned()
                    .into_any(),
                pyo3::types::PyBool::new(py, step.truncated)
                    .to_owned()
                    .into_any(),
                info_dict(py, &step.info)?.into_any(),
            ],
        )
    }

    /// The frame of the render mode (numpy array or text), or None without one.
    fn render<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        match self.with_env(py, |env| env.render())? {
            Some(frame) => Ok(Some(frame_object(py, frame)?)),
            None => Ok(None),
        }
    }

    fn close(&self) -> PyResult<()> {
        let mut guard = self.inner.lock().map_err(|_| poisoned("env"))?;
        if let Some(mut env) = guard.take() {
            env.close();
        }
        Ok(())
    }

    /// `(low, high)` of the observation space, float32.
    fn observation_bounds<'py>(&self, py: Python<'py>) -> Bounds<'py> {
        bounds(py, &self.observation_space)
    }

    /// `(low, high)` of the action space, float32.
    fn action_bounds<'py>(&self, py: Python<'py>) -> Bounds<'py> {
        bounds(py, &self.action_space)
    }

    /// The camera images beside the state, `(name, height, width, channels)` each (empty in the
    /// `state` observation mode, whose observation is the state vector alone).
    fn image_views(&self) -> Vec<(String, u32, u32, u32)> {
        image_views(self.image_space.as_ref())
    }

    /// Gymnasium's `metadata`: `render_modes` and `render_fps`.
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let guard = self.inner.lock().map_err(|_| poisoned("env"))?;
        let env = guard
            .as_ref()
            .ok_or_else(|| pyo3::exceptions::PyRuntimeError::new_err("the env is closed"))?;
        metadata_dict(py, &env.metadata())
    }

    /// The render mode chosen at construction, if any.
    #[getter]
    fn render_mode(&self) -> PyResult<Option<&'static str>> {
        let guard = self.inner.lock().map_err(|_| poisoned("env"))?;
        Ok(guard
            .as_ref()
            .and_then(|env| env.render_mode())
            .map(render_mode_name))
    }

    #[getter]
    fn env_id(&self) -> &str {
        &self.id
    }

    #[getter]
    fn rescale_action(&self) -> bool {
        self.rescale_action
    }

    /// Every setting of this env, defaults filled in, as TOML text.
    fn config_toml(&self) -> PyResult<String> {
        registry::config_toml(&self.id, &self.table).map_err(env_error)
    }

    fn __repr__(&self) -> String {
        format!(
            "Env({:?}, obs_dim={}, act_dim={}, rescale_action={})",
            self.id,
            self.observation_space.dim(),
            self.action_space.dim(),
            self.rescale_action
        )
    }
}

/// The registered env ids with one line on each.
#[pyfunction]
pub fn list_envs() -> Vec<(&'static str, &'static str)> {
    registry::specs()
        .iter()
        .map(|s| (s.id, s.summary))
        .collect()
}

/// Every setting of `env_id` (with `config` applied and checked) as TOML text.
#[pyfunction]
#[pyo3(signature = (env_id, config=None))]
pub fn env_config(env_id: &str, config: Option<&Bound<'_, PyDict>>) -> PyResult<String> {
    let recipe = EnvRecipe::new(env_id, config, false, None, None)?;
    registry::config_toml(env_id, &recipe.table).map_err(env_error)
}
