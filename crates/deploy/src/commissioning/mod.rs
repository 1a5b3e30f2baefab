//! The operator's steps before any policy runs: calibrating the joint mapping and the jog test
//! (each joint a few degrees and back, its direction confirmed by eye).

mod calibrate;
mod jog;

pub use calibrate::{CalibrationReadings, calibration_from_readings};
pub use jog::{JogOptions, JogOutcome, jog_test};
