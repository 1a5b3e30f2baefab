//! [`GuardedLink`]: the only way the deployment loop reaches the controller. It logs every
//! command, prints instead of sending in a dry run, and once tripped by a fault it has sent
//! StopMotion and ServoMoveEnd and refuses every further command.

use super::log::JsonLog;
use crate::robot::{RobotCommand, RobotLink, SideLine, StampedState};
use crate::safety::Fault;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Instant;

/// A command under way on the side line.
type Aside = (RobotCommand, JoinHandle<Result<(), String>>);

/// The deployment loop's link to the controller: logs every command, prints instead of sending
/// in a dry run, and refuses every command once a fault has tripped it.
pub struct GuardedLink {
    link: Box<dyn RobotLink>,
    live: bool,
    /// The link's second line, live only.
    side: Option<Arc<dyn SideLine>>,
    /// The one command sent aside and not yet answered.
    aside: Option<Aside>,
    /// The fault that stopped the arm, once one has.
    tripped: Option<Fault>,
    last_sequence: u64,
    /// From the fault's detection to StopMotion and ServoMoveEnd both answered.
    stopped_in: Option<std::time::Duration>,
    /// The run's log; every command and every new state goes to it.
    pub log: JsonLog,
}

impl GuardedLink {
    /// `live = false`: a dry run that reads the robot but only prints what it would send.
    pub fn new(link: Box<dyn RobotLink>, live: bool, log: JsonLog) -> Self {
        let side = if live { link.side_line() } else { None };
        Self {
            link,
            live,
            side,
            aside: None,
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

    /// The link's second line (live only): for a watcher on another thread.
    pub fn side_line(&self) -> Option<Arc<dyn SideLine>> {
        self.side.clone()
    }

    /// Sends a command without waiting for its reply, over the side line, so the servo set
    /// points keep flowing meanwhile: one at a time (an earlier one is waited for first).
    /// Without a side line (a dry run, a simulated controller) it is [`Self::send`].
    pub fn send_aside(&mut self, command: &RobotCommand) -> Result<(), Fault> {
        self.settle_aside(true)?;
        let Some(side) = self.side.clone() else {
            return self.send(command);
        };
        if self.tripped.is_some() {
            return self.send(command);
        }
        let sent = command.clone();
        let call = std::thread::spawn(move || side.send(&sent).map_err(|e| e.to_string()));
        self.aside = Some((command.clone(), call));
        Ok(())
    }

    /// Takes the reply of the command sent aside, if it has come (or, with `wait`, once it
    /// comes): its failure is the loop's fault.
    pub fn settle_aside(&mut self, wait: bool) -> Result<(), Fault> {
        match &self.aside {
            Some((_, call)) if wait || call.is_finished() => {}
            _ => return Ok(()),
        }
        let (command, call) = self.aside.take().expect("matched above");
        let result = call
            .join()
            .unwrap_or_else(|_| Err("the call's thread panicked".into()));
        self.log.sent(&command, result.clone());
        result.map_err(|message| Fault::CallFailed {
            call: command.method().into(),
            message,
        })
    }

    /// Stops the arm: StopMotion then ServoMoveEnd, whatever each returns, then refuses every
    /// later command. Returns when both calls have returned (each bounded by the link's
    /// timeout). A motion command already on its way aside (a MoveGripper) may land after
    /// them: its reply is waited for, and then both are sent again, so that the controller's
    /// last word is the stop.
    pub fn stop(&mut self, fault: &Fault) {
        if self.tripped.is_some() {
            return;
        }
        let detected = Instant::now();
        self.log.note("fault", serde_json::json!(fault.to_string()));
        self.send_stop();
        let took = detected.elapsed();
        self.stopped_in = Some(took);
        self.log
            .note("stopped_ms", serde_json::json!(took.as_secs_f64() * 1000.0));
        let in_flight_moves = self.aside.as_ref().is_some_and(|(c, _)| c.moves());
        // Its failure changes nothing now: the arm is being stopped.
        let _ = self.settle_aside(true);
        if in_flight_moves {
            self.send_stop();
        }
        self.log.flush();
        self.tripped = Some(fault.clone());
    }

    /// StopMotion then ServoMoveEnd, whatever each returns (printed in a dry run).
    fn send_stop(&mut self) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;
    use std::time::Duration;

    /// The controller's call log, in the order calls land.
    type Calls = Arc<Mutex<Vec<&'static str>>>;

    struct Link(Calls);
    struct SlowSide(Calls);

    impl RobotLink for Link {
        fn latest_state(&self) -> crate::Result<StampedState> {
            Ok(StampedState {
                state: Default::default(),
                received_at: Instant::now(),
                sequence: 0,
            })
        }
        fn send(&mut self, command: &RobotCommand) -> crate::Result<()> {
            self.0.lock().unwrap().push(command.method());
            Ok(())
        }
        fn side_line(&self) -> Option<Arc<dyn SideLine>> {
            Some(Arc::new(SlowSide(self.0.clone())))
        }
    }

    impl SideLine for SlowSide {
        /// The command lands 50 ms after it was sent.
        fn send(&self, command: &RobotCommand) -> crate::Result<()> {
            std::thread::sleep(Duration::from_millis(50));
            self.0.lock().unwrap().push(command.method());
            Ok(())
        }
    }

    #[test]
    fn a_gripper_command_landing_after_the_stop_is_followed_by_another() {
        let calls = Calls::default();
        let mut link = GuardedLink::new(
            Box::new(Link(calls.clone())),
            true,
            JsonLog::create(None).unwrap(),
        );
        let close = RobotCommand::MoveGripper {
            index: 1,
            position_percent: 0,
            speed_percent: 100,
            force_percent: 50,
            max_time_ms: 3000,
        };
        link.send_aside(&close).unwrap();
        link.stop(&Fault::Interrupted);
        // The first stop does not wait for the gripper's call; the last word is a stop.
        assert_eq!(
            *calls.lock().unwrap(),
            [
                "StopMotion",
                "ServoMoveEnd",
                "MoveGripper",
                "StopMotion",
                "ServoMoveEnd"
            ]
        );
        assert!(link.stopped_in().unwrap() < Duration::from_millis(40));
        assert!(link.send(&close).is_err(), "refused once stopped");
    }
}
