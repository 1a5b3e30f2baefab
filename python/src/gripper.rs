//! `fairgrasp.GripperRamp`: the gripper controller's set point (`fairgrasp_sim::control`), the
//! model the twin's controller and training's `[control.gripper]` share, so that another
//! simulator standing in for the arm (bench/sim2sim) moves its fingers as a FAIRINO gripper's
//! `MoveGripper` does, through the same code.

use fairgrasp_sim::control::{FINGERS_FULL_SPEED_PERCENT_PER_S, GripperRamp as Ramp};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// The gripper's set point in % of the stroke (0 closed … 100 open).
#[pyclass(module = "fairgrasp._native")]
pub struct GripperRamp(Ramp);

fn finite(name: &str, v: f64) -> PyResult<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(PyValueError::new_err(format!(
            "invalid {name}: expected a finite number, got {v}"
        )))
    }
}

#[pymethods]
impl GripperRamp {
    /// At rest at `opening_percent`.
    #[new]
    fn new(opening_percent: f64) -> PyResult<Self> {
        Ok(Self(Ramp::at(finite("opening_percent", opening_percent)?)))
    }

    /// A `MoveGripper` to `target_percent` at `speed_percent_per_s` from `fingers_percent`,
    /// where the fingers are now.
    fn command(
        &mut self,
        fingers_percent: f64,
        target_percent: f64,
        speed_percent_per_s: f64,
    ) -> PyResult<()> {
        self.0.command(
            finite("fingers_percent", fingers_percent)?,
            finite("target_percent", target_percent)?,
            finite("speed_percent_per_s", speed_percent_per_s)?,
        );
        Ok(())
    }

    /// Moves the set point on by `dt` seconds and returns it (%).
    fn advance(&mut self, dt: f64) -> PyResult<f64> {
        Ok(self.0.advance(finite("dt", dt)?))
    }

    #[getter]
    fn target(&self) -> f64 {
        self.0.target()
    }

    /// The set-point speed of a gripper at full speed (% of the stroke per second).
    #[classattr]
    fn full_speed_percent_per_s() -> f64 {
        FINGERS_FULL_SPEED_PERCENT_PER_S
    }
}
