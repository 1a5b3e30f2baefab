//! A model saved by `fairgrasp train`, acting on raw observations exactly as `fairgrasp eval`
//! and the deployment loop do (the same Rust `Policy`).

use crate::convert::f32_values;
use crate::errors::{poisoned, rl_error};
use fairgrasp_rl::Policy as NativePolicy;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::Mutex;

#[pyclass(module = "fairgrasp._native", name = "Policy")]
pub struct Policy {
    inner: Mutex<NativePolicy>,
    obs_dim: usize,
    act_dim: usize,
}

#[pymethods]
impl Policy {
    /// Loads a model directory (`runs/NAME/best`) or a run directory (its best model).
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let policy = py.detach(|| NativePolicy::load(&path)).map_err(rl_error)?;
        Ok(Self {
            obs_dim: policy.obs_dim(),
            act_dim: policy.act_dim(),
            inner: Mutex::new(policy),
        })
    }

    /// Actions for `obs`: one observation `(obs_dim,)` gives one action `(act_dim,)`, a batch
    /// `(n, obs_dim)` gives `(n, act_dim)`. Deterministic: the distribution's mode; otherwise
    /// a sample from the policy's own seeded stream. Actions are in the model's action space
    /// ([-1, 1] for the trainer's models), unclipped.
    #[pyo3(signature = (obs, deterministic=true))]
    fn act<'py>(
        &self,
        py: Python<'py>,
        obs: &Bound<'py, PyAny>,
        deterministic: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let shape: Vec<usize> = match obs.getattr("shape") {
            Ok(shape) => shape.extract()?,
            Err(_) => vec![self.obs_dim],
        };
        let batch = match shape.as_slice() {
            [n] if *n == self.obs_dim => None,
            [rows, n] if *n == self.obs_dim && *rows > 0 => Some(*rows),
            _ => {
                return Err(pyo3::exceptions::PyValueError::new_err(format!(
                    "invalid observation: expected shape ({},) or (n, {}), got {shape:?}",
                    self.obs_dim, self.obs_dim
                )));
            }
        };
        let values = f32_values(obs, "observation", &shape)?;
        let actions = py.detach(|| {
            let mut policy = self.inner.lock().map_err(|_| poisoned("policy"))?;
            match batch {
                None => policy.act(&values, deterministic),
                Some(_) => policy.act_batch(&values, deterministic),
            }
            .map_err(rl_error)
        })?;
        let array = PyArray1::from_vec(py, actions);
        Ok(match batch {
            None => array.into_any(),
            Some(rows) => array.reshape([rows, self.act_dim])?.into_any(),
        })
    }

    /// Actions of a camera policy for `state` (`(obs_dim,)` or `(n, obs_dim)`) and `images`:
    /// `uint8`, each observation's cameras' bytes one after another in `image_views` order
    /// (`(image_len,)` or `(n, image_len)`). A policy without cameras ignores `images`.
    #[pyo3(signature = (state, images, deterministic=true))]
    fn act_with_images<'py>(
        &self,
        py: Python<'py>,
        state: &Bound<'py, PyAny>,
        images: PyReadonlyArrayDyn<'py, u8>,
        deterministic: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let shape: Vec<usize> = state.getattr("shape")?.extract()?;
        let rows = match shape.as_slice() {
            [n] if *n == self.obs_dim => None,
            [rows, n] if *n == self.obs_dim && *rows > 0 => Some(*rows),
            _ => {
                return Err(pyo3::exceptions::PyValueError::new_err(format!(
                    "invalid observation: expected `state` of shape ({},) or (n, {}), got {shape:?}",
                    self.obs_dim, self.obs_dim
                )));
            }
        };
        let values = f32_values(state, "state", &shape)?;
        let bytes: Vec<u8> = images.as_array().iter().copied().collect();
        let actions = py.detach(|| {
            let mut policy = self.inner.lock().map_err(|_| poisoned("policy"))?;
            (policy.act_with_images(&values, Some(&bytes), deterministic)).map_err(rl_error)
        })?;
        let array = PyArray1::from_vec(py, actions);
        Ok(match rows {
            None => array.into_any(),
            Some(rows) => array.reshape([rows, self.act_dim])?.into_any(),
        })
    }

    /// The camera images a camera policy reads, as `(name, height, width, channels)` in the
    /// order their bytes follow one another; empty for a policy of the observation vector.
    fn image_views(&self) -> PyResult<Vec<(String, u32, u32, u32)>> {
        let policy = self.inner.lock().map_err(|_| poisoned("policy"))?;
        Ok(crate::env::image_views(policy.image_space()))
    }

    /// Restarts the stream of stochastic actions.
    fn set_seed(&self, seed: u64) -> PyResult<()> {
        self.inner
            .lock()
            .map_err(|_| poisoned("policy"))?
            .set_seed(seed);
        Ok(())
    }

    #[getter]
    fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    #[getter]
    fn act_dim(&self) -> usize {
        self.act_dim
    }

    /// `model.json` as JSON text (algorithm, env id and settings, steps trained, …).
    fn meta_json(&self) -> PyResult<String> {
        let policy = self.inner.lock().map_err(|_| poisoned("policy"))?;
        serde_json::to_string(policy.meta())
            .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))
    }

    /// The settings of the env the model was trained on, as JSON text of TOML-shaped tables.
    fn env_settings_json(&self) -> PyResult<String> {
        let policy = self.inner.lock().map_err(|_| poisoned("policy"))?;
        let table = policy.env_settings(&[]).map_err(rl_error)?;
        serde_json::to_string(&table)
            .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))
    }

    /// The model directory it was loaded from.
    #[getter]
    fn path(&self) -> PyResult<Option<PathBuf>> {
        let policy = self.inner.lock().map_err(|_| poisoned("policy"))?;
        Ok(policy.dir().map(|d| d.to_path_buf()))
    }

    fn __repr__(&self) -> PyResult<String> {
        let policy = self.inner.lock().map_err(|_| poisoned("policy"))?;
        Ok(format!(
            "Policy({} on {}, obs_dim={}, act_dim={})",
            policy.meta().algo.algo(),
            policy.env_id(),
            self.obs_dim,
            self.act_dim
        ))
    }
}
