//! N environments stepped by a Rust thread pool with the GIL released: the engine of
//! `fairgrasp.make_vec_env` (an SB3 `VecEnv`) and of `fairgrasp.FairgraspVectorEnv` (Gymnasium's
//! `VectorEnv`). A step takes one `(n, act_dim)` float32 batch and returns one `(n, obs_dim)`
//! batch: the observations are copied once, as a whole, from the vector env's buffer.

use crate::convert::{
    Bounds, batch_observation, bounds, f32_values, frame_object, info_dict, metadata_dict,
    obs_info, observation, render_mode_name,
};
use crate::env::{EnvRecipe, image_views};
use crate::errors::{env_error, poisoned, with_open};
use fairgrasp_env::spaces::{BoxSpace, ImageSpace};
use fairgrasp_env::{EpisodeEnd, Info, VecEnv as NativeVecEnv, VectorEnv};
use numpy::PyArray1;
use pyo3::exceptions::{PyIndexError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use std::sync::Mutex;
use std::time::Instant;

type Envs = NativeVecEnv<Box<dyn fairgrasp_env::Env>>;

/// What one step produced, copied out of the vector env's buffers while the GIL was released.
struct StepOut {
    obs: Vec<f32>,
    images: Vec<u8>,
    rewards: Vec<f32>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
    infos: Vec<Info>,
    ends: Vec<Option<EpisodeEnd>>,
}

fn env_at(
    envs: &mut Envs,
    index: usize,
) -> fairgrasp_env::Result<&mut Box<dyn fairgrasp_env::Env>> {
    envs.env_mut(index)
        .ok_or_else(|| fairgrasp_env::EnvError::Usage(format!("no env {index}")))
}

#[pyclass(module = "fairgrasp._native", name = "VecEnv")]
pub struct VecEnv {
    inner: Mutex<Option<Envs>>,
    recipe: EnvRecipe,
    num_envs: usize,
    obs_dim: usize,
    act_dim: usize,
    observation_space: BoxSpace,
    image_space: Option<ImageSpace>,
    action_space: BoxSpace,
    threads: usize,
    started: Instant,
}

impl VecEnv {
    fn with_envs<T: Send>(
        &self,
        py: Python<'_>,
        f: impl FnOnce(&mut Envs) -> fairgrasp_env::Result<T> + Send,
    ) -> PyResult<T> {
        with_open(py, &self.inner, "vector env", f)
    }

    fn batch<'py>(
        &self,
        py: Python<'py>,
        obs: Vec<f32>,
        images: &[u8],
    ) -> PyResult<Bound<'py, PyAny>> {
        batch_observation(py, self.num_envs, obs, self.image_space.as_ref(), images)
    }

    fn check_index(&self, index: usize) -> PyResult<()> {
        if index < self.num_envs {
            Ok(())
        } else {
            Err(PyIndexError::new_err(format!(
                "env index {index} is out of range: there are {} envs",
                self.num_envs
            )))
        }
    }
}

#[pymethods]
impl VecEnv {
    /// `num_envs` copies of `env_id` built from `config`, stepped by `threads` Rust threads
    /// (0: one per CPU, at most one per env).
    #[new]
    #[pyo3(signature = (env_id, num_envs, config=None, threads=0, rescale_action=true, render_mode=None, obs_mode=None))]
    #[allow(clippy::too_many_arguments)] // Python's keyword arguments
    fn new(
        py: Python<'_>,
        env_id: &str,
        num_envs: usize,
        config: Option<&Bound<'_, PyDict>>,
        threads: usize,
        rescale_action: bool,
        render_mode: Option<&str>,
        obs_mode: Option<&str>,
    ) -> PyResult<Self> {
        if num_envs == 0 {
            return Err(PyValueError::new_err("num_envs must be at least 1"));
        }
        let recipe = EnvRecipe::new(env_id, config, rescale_action, render_mode, obs_mode)?;
        let envs = py
            .detach(|| {
                let envs = (0..num_envs)
                    .map(|_| recipe.build())
                    .collect::<fairgrasp_env::Result<Vec<_>>>()?;
                NativeVecEnv::new(envs, threads)
            })
            .map_err(env_error)?;
        Ok(Self {
            num_envs,
            obs_dim: envs.obs_dim(),
            act_dim: envs.act_dim(),
            observation_space: envs.observation_space().clone(),
            image_space: envs.image_space().cloned(),
            action_space: envs.action_space().clone(),
            threads: envs.num_threads(),
            inner: Mutex::new(Some(envs)),
            recipe,
            started: Instant::now(),
        })
    }

    #[getter]
    fn num_envs(&self) -> usize {
        self.num_envs
    }

    #[getter]
    fn threads(&self) -> usize {
        self.threads
    }

    #[getter]
    fn env_id(&self) -> &str {
        &self.recipe.id
    }

    /// Resets every env (env `i` with `seed + i` when a seed is given): `(observations,
    /// infos)`.
    #[pyo3(signature = (seed=None))]
    fn reset<'py>(&self, py: Python<'py>, seed: Option<u64>) -> PyResult<Bound<'py, PyTuple>> {
        let (obs, images, infos) = self.with_envs(py, |envs| {
            let obs = envs.reset(seed)?.to_vec();
            Ok((obs, envs.images().to_vec(), envs.reset_infos().to_vec()))
        })?;
        let infos = PyList::new(
            py,
            infos
                .iter()
                .map(|info| info_dict(py, info))
                .collect::<PyResult<Vec<_>>>()?,
        )?;
        PyTuple::new(py, [self.batch(py, obs, &images)?, infos.into_any()])
    }

    /// Resets env `index` alone: `(observation, info)`.
    #[pyo3(signature = (index, seed=None))]
    fn reset_env<'py>(
        &self,
        py: Python<'py>,
        index: usize,
        seed: Option<u64>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        self.check_index(index)?;
        let (obs, image, info) = self.with_envs(py, |envs| {
            let obs = envs.reset_env(index, seed)?.to_vec();
            let image = env_at(envs, index)?.image().map(<[u8]>::to_vec);
            Ok((obs, image, envs.reset_infos()[index].clone()))
        })?;
        let images = self.image_space.as_ref().zip(image.as_deref());
        obs_info(py, observation(py, obs, images)?, &info)
    }

    /// Steps every env with its row of `actions` (`(num_envs, act_dim)`), resetting those whose
    /// episode ends: `(observations, rewards, terminated, truncated, infos)`. The info of an env
    /// whose episode ended holds `terminal_observation`, `TimeLimit.truncated`, `episode`
    /// (`r`, `l`, `t`, as SB3's Monitor writes it) and `reset_info`.
    fn step<'py>(
        &self,
        py: Python<'py>,
        actions: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let actions = f32_values(actions, "actions", &[self.num_envs, self.act_dim])?;
        let out = self.with_envs(py, move |envs| {
            let step = envs.step(&actions)?;
            Ok(StepOut {
                obs: step.observations.to_vec(),
                images: step.images.to_vec(),
                rewards: step.rewards.to_vec(),
                terminated: step.terminated.to_vec(),
                truncated: step.truncated.to_vec(),
                infos: step.infos.to_vec(),
                ends: step.episode_ends.to_vec(),
            })
        })?;
        let elapsed = self.started.elapsed().as_secs_f64();
        let mut infos = Vec::with_capacity(self.num_envs);
        for (i, (info, end)) in out.infos.iter().zip(out.ends).enumerate() {
            let dict = info_dict(py, info)?;
            if let Some(end) = end {
                let images = self.image_space.as_ref().zip(Some(&end.terminal_image[..]));
                dict.set_item(
                    "terminal_observation",
                    observation(py, end.terminal_observation, images)?,
                )?;
                dict.set_item(
                    "TimeLimit.truncated",
                    out.truncated[i] && !out.terminated[i],
                )?;
                let episode = PyDict::new(py);
                episode.set_item("r", end.episode.episode_return)?;
                episode.set_item("l", end.episode.length)?;
                episode.set_item("t", (elapsed * 1e6).round() / 1e6)?;
                dict.set_item("episode", episode)?;
                dict.set_item("reset_info", info_dict(py, &end.reset_info)?)?;
            }
            infos.push(dict);
        }
        PyTuple::new(
            py,
            [
                self.batch(py, out.obs, &out.images)?,
                PyArray1::from_vec(py, out.rewards).into_any(),
                PyArray1::from_vec(py, out.terminated).into_any(),
                PyArray1::from_vec(py, out.truncated).into_any(),
                PyList::new(py, infos)?.into_any(),
            ],
        )
    }

    /// The current observations (those last returned).
    fn observations<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let (obs, images) = self.with_envs(py, |envs| {
            Ok((envs.observations().to_vec(), envs.images().to_vec()))
        })?;
        self.batch(py, obs, &images)
    }

    /// Env `index`'s frame in the render mode, or None without one.
    fn render_env<'py>(
        &self,
        py: Python<'py>,
        index: usize,
    ) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.check_index(index)?;
        match self.with_envs(py, |envs| env_at(envs, index)?.render())? {
            Some(frame) => Ok(Some(frame_object(py, frame)?)),
            None => Ok(None),
        }
    }

    /// `(low, high)` of one env's observation space.
    fn observation_bounds<'py>(&self, py: Python<'py>) -> Bounds<'py> {
        bounds(py, &self.observation_space)
    }

    /// The camera images beside the state, `(name, height, width, channels)` each (empty in the
    /// `state` observation mode).
    fn image_views(&self) -> Vec<(String, u32, u32, u32)> {
        image_views(self.image_space.as_ref())
    }

    /// `(low, high)` of one env's action space.
    fn action_bounds<'py>(&self, py: Python<'py>) -> Bounds<'py> {
        bounds(py, &self.action_space)
    }

    /// Gymnasium's `metadata` of one env.
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let meta = self.with_envs(py, |envs| Ok(env_at(envs, 0)?.metadata()))?;
        metadata_dict(py, &meta)
    }

    /// The render mode chosen at construction, if any.
    #[getter]
    fn render_mode(&self, py: Python<'_>) -> PyResult<Option<&'static str>> {
        let mode = self.with_envs(py, |envs| Ok(env_at(envs, 0)?.render_mode()))?;
        Ok(mode.map(render_mode_name))
    }

    /// Every setting of the envs, defaults filled in, as TOML text.
    fn config_toml(&self) -> PyResult<String> {
        fairgrasp_env::registry::config_toml(&self.recipe.id, &self.recipe.table).map_err(env_error)
    }

    fn close(&self) -> PyResult<()> {
        let mut guard = self.inner.lock().map_err(|_| poisoned("vector env"))?;
        if let Some(mut envs) = guard.take() {
            envs.close();
        }
        Ok(())
    }

    fn __repr__(&self) -> String {
        format!(
            "VecEnv({:?}, num_envs={}, threads={}, obs_dim={}, act_dim={})",
            self.recipe.id, self.num_envs, self.threads, self.obs_dim, self.act_dim
        )
    }
}
