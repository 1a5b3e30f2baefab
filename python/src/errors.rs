//! Rust errors as Python exceptions. Every message is the Rust one, which names the key, the
//! file or the value at fault; the class says what kind of fault it is, so callers can catch
//! `fairgrasp.ConfigError` apart from `fairgrasp.ActionError` (both are `ValueError`s).

use fairgrasp_env::EnvError;
use fairgrasp_rl::error::RlError;
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;

pyo3::create_exception!(
    fairgrasp,
    ConfigError,
    PyValueError,
    "A setting that is unknown, mistyped or out of range; the message names the key."
);
pyo3::create_exception!(
    fairgrasp,
    ActionError,
    PyValueError,
    "An action that cannot be applied: wrong shape, NaN or infinite values."
);
pyo3::create_exception!(
    fairgrasp,
    ModelError,
    PyRuntimeError,
    "A saved model or checkpoint that cannot be used: missing, corrupt or mismatched."
);

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("ConfigError", py.get_type::<ConfigError>())?;
    m.add("ActionError", py.get_type::<ActionError>())?;
    m.add("ModelError", py.get_type::<ModelError>())?;
    Ok(())
}

pub fn env_error(e: EnvError) -> PyErr {
    let message = e.to_string();
    match e {
        EnvError::Action(_) => ActionError::new_err(message),
        EnvError::Config { .. } => ConfigError::new_err(message),
        EnvError::File { .. } => PyOSError::new_err(message),
        _ => PyRuntimeError::new_err(message),
    }
}

pub fn rl_error(e: RlError) -> PyErr {
    let message = e.to_string();
    match e {
        RlError::Env(e) => env_error(e),
        RlError::Config { .. } => ConfigError::new_err(message),
        RlError::Model(_) => ModelError::new_err(message),
        _ => PyRuntimeError::new_err(message),
    }
}

/// A poisoned lock means a panic interrupted an earlier call on this object.
pub fn poisoned(what: &str) -> PyErr {
    PyRuntimeError::new_err(format!(
        "this {what} is unusable: an earlier call panicked inside it; create a new one"
    ))
}

/// Runs `f` on the env (or vector env, `what`) in `cell` with the GIL released; an error when it
/// is closed or an earlier call panicked inside it.
pub fn with_open<S: Send, T: Send>(
    py: Python<'_>,
    cell: &std::sync::Mutex<Option<S>>,
    what: &str,
    f: impl FnOnce(&mut S) -> fairgrasp_env::Result<T> + Send,
) -> PyResult<T> {
    py.detach(|| {
        let mut guard = cell.lock().map_err(|_| poisoned(what))?;
        let open = guard
            .as_mut()
            .ok_or_else(|| PyRuntimeError::new_err(format!("the {what} is closed")))?;
        f(open).map_err(env_error)
    })
}
