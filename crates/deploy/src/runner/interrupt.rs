//! Ctrl-C stops the arm in every phase, not only between servo ticks: a watcher thread sends
//! StopMotion over the link's side line as soon as the flag is raised, whatever the loop is
//! waiting on (a blocking MoveJ, a reply, the operator's prompt). The loop then sees the
//! flag, or its blocked call fails, and stops as for any fault.

use crate::robot::{RobotCommand, SideLine};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How often the flag is looked at: the ctrlc handler only sets it, so it is polled. Two
/// milliseconds is a fiftieth of the 100 ms allowed for the arm to come to rest.
const POLL: Duration = Duration::from_millis(2);

/// What the watcher did.
#[derive(Debug)]
pub struct InterruptStop {
    /// From the flag seen to StopMotion answered.
    pub took: Duration,
    /// StopMotion's outcome, the error as text.
    pub result: Result<(), String>,
}

/// Watches `interrupt` until `done`; on the flag sends StopMotion once over `line`.
pub fn watch(
    interrupt: &AtomicBool,
    done: &AtomicBool,
    line: &dyn SideLine,
) -> Option<InterruptStop> {
    loop {
        if interrupt.load(Ordering::Relaxed) {
            let seen = Instant::now();
            let result = line
                .send(&RobotCommand::StopMotion)
                .map_err(|e| e.to_string());
            if let Err(e) = &result {
                eprintln!("Ctrl-C: StopMotion failed: {e}");
            }
            return Some(InterruptStop {
                took: seen.elapsed(),
                result,
            });
        }
        if done.load(Ordering::Relaxed) {
            return None;
        }
        std::thread::sleep(POLL);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[derive(Default)]
    struct Recorder(Mutex<Vec<&'static str>>);

    impl SideLine for Recorder {
        fn send(&self, command: &RobotCommand) -> crate::Result<()> {
            self.0.lock().unwrap().push(command.method());
            Ok(())
        }
    }

    #[test]
    fn the_flag_sends_one_stop_motion_and_done_sends_none() {
        let line = Recorder::default();
        let interrupt = AtomicBool::new(false);
        let done = AtomicBool::new(true);
        assert!(watch(&interrupt, &done, &line).is_none());
        assert!(line.0.lock().unwrap().is_empty());

        let done = AtomicBool::new(false);
        let stop = std::thread::scope(|s| {
            let watcher = s.spawn(|| watch(&interrupt, &done, &line));
            std::thread::sleep(Duration::from_millis(20));
            assert!(line.0.lock().unwrap().is_empty(), "sent before the flag");
            interrupt.store(true, Ordering::Relaxed);
            watcher.join().unwrap()
        });
        assert!(stop.unwrap().result.is_ok());
        assert_eq!(*line.0.lock().unwrap(), vec!["StopMotion"]);
    }
}
