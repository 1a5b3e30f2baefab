//! System identification of the arm's drives: what the arm adds, between the controller's set
//! point and the joint, to the training simulator's own PD joints.
//!
//! - [`plan`]: the excitation, one joint at a time (steps, then a chirp), a few degrees about
//!   the present pose, well under the safety caps;
//! - [`record`]: running it through the safety layer and recording every set point sent and
//!   every state received, then timing the gripper closing on nothing;
//! - [`replay`]: the recorded set points through the simulated arm (the model in the loop);
//! - [`fit`]: per joint, the pure delay and first-order lag that make the simulator match;
//! - [`model`]: the TOML file the twin (`fairgrasp twin --drives`) reads.
//!
//! The fit is of the dynamics the simulator lacks, not of the whole response: the simulated
//! joints lag their targets by themselves, so a delay and lag fitted to the set point →
//! joint response would count that lag twice once added to the simulator. On the twin, whose
//! arm *is* the simulator, the drives injected (`tracking=…`) are what comes out.

pub mod fit;
pub mod model;
pub mod plan;
pub mod record;
pub mod replay;

pub use fit::JointFit;
pub use model::{DriveModel, GripperTiming, JointDrive};
pub use plan::ExcitationPlan;
pub use record::{RecordOptions, Recording, record};
pub use replay::ArmSim;

use crate::error::{DeployError, Result};
use crate::twin::faults::{JointTracking, TrackingModel};
use fit::{Samples, Uniform};

/// The fitted samples start this long before a segment's end is cut (s): the window the
/// delay looks back over.
const LOOKBACK_S: f64 = 0.3;

/// Fits each excited joint of `recording` against `sim`, then replays the recording through
/// the simulator with every fitted drive in place to measure what is left unexplained.
pub fn identify(recording: &Recording, sim: &ArmSim) -> Result<DriveModel> {
    if recording.segments.is_empty() {
        return Err(DeployError::config(
            "system identification",
            "the recording excited no joint",
        ));
    }
    let recording = &recording.aligned();
    let times = recording.state_times();
    let plain = sim.replay(recording, &TrackingModel::default())?;
    let mut tracking = TrackingModel::default();
    let mut fits = Vec::new();
    for segment in &recording.segments {
        let j = segment.joint - 1;
        let samples = samples(recording, &times, j, segment.start, segment.end);
        let simulated = window(&plain[j], segment.start - LOOKBACK_S, segment.end);
        let fit = fit::fit_joint(&simulated, &samples)
            .map_err(|e| DeployError::config(format!("joint {}", segment.joint), e.to_string()))?;
        tracking[j] = JointTracking {
            delay_ms: fit.delay_ms,
            tau_ms: fit.tau_ms,
        };
        fits.push((segment, fit, samples));
    }
    let checked = sim.replay(recording, &tracking)?;
    let joints = fits
        .into_iter()
        .map(|(segment, fit, samples)| {
            let (rms, _) = fit::residual(&checked[segment.joint - 1], &samples);
            JointDrive {
                joint: segment.joint,
                delay_ms: round(fit.delay_ms, 2),
                tau_ms: round(fit.tau_ms, 2),
                rms_residual_deg: round(rms, 5),
                samples: samples.t.len(),
            }
        })
        .collect();
    Ok(DriveModel {
        env: sim.env_id.clone(),
        joints,
        gripper: recording.gripper.clone(),
    })
}

fn round(v: f64, decimals: i32) -> f64 {
    let k = 10f64.powi(decimals);
    (v * k).round() / k
}

/// Joint `j`'s readings between `from` and `to` (s).
fn samples(recording: &Recording, times: &[f64], j: usize, from: f64, to: f64) -> Samples {
    let mut s = Samples::default();
    for (state, &t) in recording.states.iter().zip(times) {
        if t >= from && t <= to {
            s.t.push(t);
            s.q.push(state.joints_deg[j]);
        }
    }
    s
}

/// `signal` between `from` and `to` (s), whole samples.
fn window(signal: &Uniform, from: f64, to: f64) -> Uniform {
    let first =
        (((from - signal.t0) / signal.dt).floor().max(0.0) as usize).min(signal.values.len());
    let last = ((((to - signal.t0) / signal.dt).ceil() as usize) + 1).min(signal.values.len());
    Uniform {
        t0: signal.t0 + first as f64 * signal.dt,
        dt: signal.dt,
        values: signal.values[first..last.max(first)].to_vec(),
    }
}
