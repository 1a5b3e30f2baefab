//! The deployment-matched evaluation's episodes (`fairgrasp eval --deployment`): the deployment
//! loop on a [`SimulatedController`], placement after placement.
//!
//! A fault stops the arm and ends a deployment run, as it must on a robot. Here it counts as a
//! failed episode; the controller's fault is then cleared as an operator clears it
//! (`ResetAllError`), and the evaluation goes on from the next placement with a fresh loop.
//! Without the reset, one collision latched on the controller failed every later episode.

use super::simulated::SimulatedController;
use crate::calibration::Calibration;
use crate::error::Result;
use crate::robot::{RobotCommand, RobotLink};
use crate::runner::{DeployOptions, Deployment, EpisodeHost, JsonLog};
use fairgrasp_rl::Policy;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// What the episodes came to.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Evaluation {
    /// Episodes played, those a fault stopped included.
    pub played: u32,
    /// Episodes the twin judged a success (by the task's rule).
    pub successes: u32,
    /// The fault of each episode stopped by one, in order.
    pub faults: Vec<String>,
    /// The loop's warnings about the model against the deployment (from the first loop).
    pub mismatches: Vec<String>,
}

/// Plays `options.episodes` episodes of the model in `model` on `link`, episode `i` placed from
/// `seed + i`. With `log`, each loop writes the deployment's log there (a loop started after a
/// fault to the next free numbered file beside it, its episodes counted from 0 again).
pub fn evaluate(
    link: &SimulatedController,
    model: &Path,
    calibration: &Calibration,
    options: &DeployOptions,
    seed: u64,
    log: Option<&Path>,
) -> Result<Evaluation> {
    let mut out = Evaluation::default();
    while out.played < options.episodes {
        let mut deployment = Deployment::new(
            Box::new(link.clone()),
            Policy::load(model)?,
            calibration.clone(),
            DeployOptions {
                episodes: options.episodes - out.played,
                ..options.clone()
            },
            JsonLog::create(log)?,
            Arc::new(AtomicBool::new(false)),
        )?;
        if out.played == 0 {
            out.mismatches = deployment.mismatches();
        }
        if let Some(frames) = link.frame_source() {
            deployment.set_camera(Box::new(frames));
        }
        let mut host = link.host_from(seed + out.played as u64);
        let report = deployment.run(&mut host, &mut link.pose_source())?;
        out.played += report.episodes.len() as u32;
        out.successes += (report.episodes.iter())
            .filter(|e| e.success == Some(true))
            .count() as u32;
        if let Some(fault) = report.fault {
            out.faults.push(fault.to_string());
            out.played += 1;
            // The next placement first: an arm still pressing where it collided would raise
            // the collision again at once and fail the next loop before it moved.
            link.host_from(seed + out.played as u64).begin(0)?;
            link.clone().send(&RobotCommand::ResetAllError)?;
        }
    }
    Ok(out)
}
