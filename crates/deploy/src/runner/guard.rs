//! [`GuardedLink`]: the only way the deployment loop reaches the controller. It logs every
//! command, prints instead of sending in a dry run, and once tripped by a fault it has sent
//! StopMotion and ServoMoveEnd and refuses every further command.

use super::log::JsonLog;
use crate::robot::{RobotCommand, RobotLink, StampedState};
use crate::safety::Fault;
use std::time::Instant;

pub struct GuardedLink {
    link: Box<dyn RobotLink>,
    live: bool,
    /// The fault that stopped the arm, once one has.
    tripped: Option<Fault>,
    last_sequence: u64,
    /// From the fault's detection to StopMotion and ServoMoveEnd both answered.
    stopped_in: Option<std::time::Duration>,
    pub log: JsonLog,
}

impl GuardedLink {
    /// `live = false`: a dry run that reads the robot but only prints what it would send.
    pub fn new(link: Box<dyn RobotLink>, live: bool, log: JsonLog) -> Self {
        Self {
            link,
            live,
            tripped: None,
            last_sequence: u64::MAX,
            stopped_in: None,
            log,
        }
    }

    /// The newest state, logged once per new report.
    pub fn state(&mut self) -> Result<StampedState, Fault> {
        let s = self
            .link
            .latest_state()
            .map_err(|e| Fault::StreamFailed(e.to_string()))?;
        if s.sequence != self.last_sequence {
            self.last_sequence = s.sequence;
            self.log.state(s.sequence, &s.state);
        }
        Ok(s)
    }

    /// Sends a command (prints it in a dry run). Refused once tripped.
    pub fn send(&mut self, command: &RobotCommand) -> Result<(), Fault> {
        if let Some(fault) = &self.tripped {
            return Err(Fault::CallFailed {
                call: command.method().into(),
                message: format!("refused: the arm was stopped ({})", fault.kind()),
            });
        }
        if !self.live {
            println!("dry run: would send {}", describe(command));
            self.log.sent(command, Ok(()));
            return Ok(());
        }
        let result = self.link.send(command).map_err(|e| e.to_string());
        self.log.sent(command, result.clone());
        result.map_err(|message| Fault::CallFailed {
            call: command.method().into(),
            message,
        })
    }

    /// Stops the arm: StopMotion then ServoMoveEnd, whatever each returns, then refuses every
    /// later command. Returns when both calls have returned (each bounded by the link's
    /// timeout).
    pub fn stop(&mut self, fault: &Fault) {
        if self.tripped.is_some() {
            return;
        }
        let detected = Instant::now();
        self.log.note("fault", serde_json::json!(fault.to_string()));
        for command in [RobotCommand::StopMotion, RobotCommand::ServoMoveEnd] {
            if self.live {
                let result = self.link.send(&command).map_err(|e| e.to_string());
                if let Err(e) = &result {
                    eprintln!("while stopping: {} failed: {e}", command.method());
                }
                self.log.sent(&command, result);
            } else {
                println!("dry run: would send {}", describe(&command));
                self.log.sent(&command, Ok(()));
            }
        }
        let took = detected.elapsed();
        self.stopped_in = Some(took);
        self.log
            .note("stopped_ms", serde_json::json!(took.as_secs_f64() * 1000.0));
        self.log.flush();
        self.tripped = Some(fault.clone());
    }

    /// The link's clock ([`RobotLink::now`]).
    pub fn now(&self) -> Instant {
        self.link.now()
    }

    /// Waits until `t` on the link's clock ([`RobotLink::sleep_until`]).
    pub fn sleep_until(&mut self, t: Instant) {
        self.link.sleep_until(t)
    }

    /// How long stopping took, from the fault's detection to both calls answered.
    pub fn stopped_in(&self) -> Option<std::time::Duration> {
        self.stopped_in
    }
}

/// One line for the operator.
pub fn describe(command: &RobotCommand) -> String {
    let joints = |q: &[f64; 6], decimals: usize| {
        q.iter()
            .map(|v| format!("{v:.decimals$}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    match command {
        RobotCommand::ServoJ { joints_deg, cmd_t } => {
            format!("ServoJ [{}] deg, cmdT {cmd_t} s", joints(joints_deg, 3))
        }
        RobotCommand::MoveJ {
            joints_deg,
            speed_percent,
            acc_percent,
        } => format!(
            "MoveJ [{}] deg at {speed_percent:.1} % speed, {acc_percent:.1} % acceleration",
            joints(joints_deg, 2)
        ),
        other => format!("{other:?}"),
    }
}
