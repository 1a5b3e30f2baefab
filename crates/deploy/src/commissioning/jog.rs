//! The jog test: each joint a few degrees slowly and back, the operator confirming the
//! direction — the design's step-by-step check before a policy runs.

use crate::calibration::Calibration;
use crate::error::{DeployError, Result};
use crate::robot::{RobotCommand, RobotLink};
use crate::safety::{Fault, SafetyFilter, Watchdog};
use std::time::Instant;

/// How far and how fast.
#[derive(Clone, Debug)]
pub struct JogOptions {
    /// Jog size (deg), at most 10.
    pub degrees: f64,
    /// MoveJ speed (% of the controller's maximum), at most 30.
    pub speed_percent: f64,
    /// The joints to test (1-based).
    pub joints: Vec<usize>,
    /// Send the moves (false: print them).
    pub live: bool,
}

impl Default for JogOptions {
    fn default() -> Self {
        Self {
            degrees: 5.0,
            speed_percent: 10.0,
            joints: (1..=6).collect(),
            live: false,
        }
    }
}

/// One joint's result.
#[derive(Clone, Debug, PartialEq)]
pub struct JogOutcome {
    /// The joint tested (1-based).
    pub joint: usize,
    /// The jog in robot degrees (its sign: the simulator's positive direction).
    pub jog_deg: f64,
    /// How far the joint moved (deg), measured.
    pub measured_deg: f64,
    /// The operator's answer (dry run: none).
    pub confirmed: Option<bool>,
}

/// Runs the test. `ask` shows a question and returns the operator's yes or no. Stops the arm
/// and returns the fault on any watchdog or call failure.
pub fn jog_test(
    link: &mut dyn RobotLink,
    calibration: &Calibration,
    filter: &SafetyFilter,
    watchdog: &Watchdog,
    options: &JogOptions,
    ask: &mut dyn FnMut(&str) -> Result<bool>,
) -> Result<Vec<JogOutcome>> {
    if !(options.degrees > 0.0 && options.degrees <= 10.0) {
        return Err(DeployError::config("--degrees", "must be in (0, 10]"));
    }
    if !(options.speed_percent > 0.0 && options.speed_percent <= 30.0) {
        return Err(DeployError::config("--speed-percent", "must be in (0, 30]"));
    }
    if let Some(j) = options.joints.iter().find(|j| !(1..=6).contains(*j)) {
        return Err(DeployError::config(
            "--joints",
            format!("joint {j} does not exist (1–6)"),
        ));
    }
    let mut outcomes = Vec::new();
    let result = (|| -> std::result::Result<(), Fault> {
        for &joint in &options.joints {
            let i = joint - 1;
            let start = read(link, watchdog)?;
            // The simulator's positive direction, in robot degrees.
            let positive = calibration.joints[i].sign as f64 * options.degrees;
            let mut target = start;
            target[i] += positive;
            if filter.check_path(&start, &target).is_err() {
                target[i] = start[i] - positive;
            }
            if let Err(fault) = filter.check_path(&start, &target) {
                return Err(Fault::UnsafeStart(format!(
                    "joint {joint} cannot move {} deg either way inside the limits, the \
                     workspace box and the arm's clearance ({fault}); move the arm nearer the \
                     home pose",
                    options.degrees
                )));
            }
            let jog = target[i] - start[i];
            let way = if jog * calibration.joints[i].sign as f64 > 0.0 {
                "positive"
            } else {
                "negative"
            };
            println!(
                "joint {joint}: {jog:+.1} deg on the robot ({way} in the simulator: \
                 right-hand rule about the joint's axis), then back"
            );
            move_j(link, &target, options)?;
            let reached = if options.live {
                read(link, watchdog)?
            } else {
                target
            };
            let confirmed = if options.live {
                Some(
                    ask(&format!(
                        "joint {joint}: did it turn {way} (right-hand rule about its axis, as \
                         the simulator's joint {joint})? [y/n]"
                    ))
                    .map_err(|e| Fault::CallFailed {
                        call: "operator".into(),
                        message: e.to_string(),
                    })?,
                )
            } else {
                None
            };
            move_j(link, &start, options)?;
            outcomes.push(JogOutcome {
                joint,
                jog_deg: jog,
                measured_deg: reached[i] - start[i],
                confirmed,
            });
        }
        Ok(())
    })();
    if let Err(fault) = result {
        if options.live {
            let _ = link.send(&RobotCommand::StopMotion);
        }
        return Err(DeployError::Other(format!("stopped the arm: {fault}")));
    }
    Ok(outcomes)
}

fn read(link: &mut dyn RobotLink, watchdog: &Watchdog) -> std::result::Result<[f64; 6], Fault> {
    let s = link
        .latest_state()
        .map_err(|e| Fault::StreamFailed(e.to_string()))?;
    watchdog.check(&s, Instant::now())?;
    Ok(s.state.joints_deg)
}

fn move_j(
    link: &mut dyn RobotLink,
    target: &[f64; 6],
    options: &JogOptions,
) -> std::result::Result<(), Fault> {
    let command = RobotCommand::MoveJ {
        joints_deg: *target,
        speed_percent: options.speed_percent,
        acc_percent: options.speed_percent,
    };
    if !options.live {
        println!("dry run: would send {}", crate::runner::describe(&command));
        return Ok(());
    }
    link.send(&command).map_err(|e| Fault::CallFailed {
        call: "MoveJ".into(),
        message: e.to_string(),
    })
}
