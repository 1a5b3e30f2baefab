//! `fairgrasp._native`, the Rust half of fairgrasp's Python package: the registered envs one at a
//! time ([`env::Env`]) and as a batch stepped by Rust threads with the GIL released
//! ([`vec_env::VecEnv`]), saved policies ([`policy::Policy`]) and the native trainer
//! ([`train::train`], [`train::evaluate`]), and a saved model driven as the deployment loop
//! drives it, by readings from another simulator ([`driver::PolicyDriver`]), with the gripper
//! controller's set point ([`gripper::GripperRamp`]). The Python package
//! (python/fairgrasp) puts Gymnasium's and Stable-Baselines3's faces on them; errors cross as
//! Python exceptions that carry the Rust message ([`errors`]).

use pyo3::prelude::*;

mod convert;
mod driver;
mod env;
mod errors;
mod gripper;
mod policy;
mod train;
mod vec_env;

#[pymodule]
#[pyo3(name = "_native")]
fn fairgrasp_native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // As the CLI does at start: a mistyped kernel choice is refused, not silently replaced.
    fairgrasp_rl::kernels::product::ProductKernel::from_env()
        .map_err(errors::ConfigError::new_err)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<env::Env>()?;
    m.add_class::<vec_env::VecEnv>()?;
    m.add_class::<policy::Policy>()?;
    m.add_class::<driver::PolicyDriver>()?;
    m.add_class::<gripper::GripperRamp>()?;
    m.add_function(wrap_pyfunction!(env::list_envs, m)?)?;
    m.add_function(wrap_pyfunction!(env::env_config, m)?)?;
    m.add_function(wrap_pyfunction!(train::train, m)?)?;
    m.add_function(wrap_pyfunction!(train::evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(train::default_train_config, m)?)?;
    errors::register(m)?;
    Ok(())
}
