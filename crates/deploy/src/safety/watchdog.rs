//! [`Watchdog`]: is the controller's newest state fit to act on?

use super::Fault;
use crate::robot::StampedState;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Judges each state report: fresh enough (received in time, and the controller's clock
/// moving), no fault code, no e-stop, no safety stop, no collision.
#[derive(Debug)]
pub struct Watchdog {
    deadline: Duration,
    meaning: fn(i64) -> &'static str,
    /// The controller's clock as last seen changing, and when that report arrived.
    clock: Mutex<Option<(i64, Instant)>>,
}

impl Clone for Watchdog {
    fn clone(&self) -> Self {
        Self::new(self.deadline, self.meaning)
    }
}

impl Watchdog {
    /// `meaning` turns a controller error code into words (the protocol's table).
    pub fn new(deadline: Duration, meaning: fn(i64) -> &'static str) -> Self {
        Self {
            deadline,
            meaning,
            clock: Mutex::new(None),
        }
    }

    /// How old a state may be, and how long the controller's clock may stand still.
    pub fn deadline(&self) -> Duration {
        self.deadline
    }

    /// `Ok` when the state may be acted on at `now`; else the fault, most severe first.
    pub fn check(&self, stamped: &StampedState, now: Instant) -> Result<(), Fault> {
        let s = &stamped.state;
        if s.emergency_stop {
            return Err(Fault::EmergencyStop);
        }
        if let Some(i) = s.safety_stop.iter().position(|&on| on) {
            return Err(Fault::SafetyStop(i));
        }
        // A collision comes with a fault code too; the collision is the cause, so it is named.
        if s.collision {
            return Err(Fault::Collision);
        }
        if s.main_code != 0 {
            return Err(Fault::ControllerFault {
                main_code: s.main_code,
                sub_code: s.sub_code,
                meaning: (self.meaning)(s.main_code as i64).to_string(),
            });
        }
        if let Some(t) = s.controller_clock_ms {
            let mut clock = self.clock.lock().unwrap_or_else(|p| p.into_inner());
            match *clock {
                Some((seen, _)) if seen == t => {}
                _ => *clock = Some((t, stamped.received_at)),
            }
            let (_, since) = clock.expect("set above");
            let frozen = stamped.received_at.saturating_duration_since(since);
            if frozen > self.deadline {
                return Err(Fault::FrozenState {
                    for_ms: frozen.as_secs_f64() * 1000.0,
                    deadline_ms: self.deadline.as_secs_f64() * 1000.0,
                });
            }
        }
        let age = now.saturating_duration_since(stamped.received_at);
        if age > self.deadline {
            return Err(Fault::StaleState {
                age_ms: age.as_secs_f64() * 1000.0,
                deadline_ms: self.deadline.as_secs_f64() * 1000.0,
            });
        }
        if let Some(i) = s.joints_deg.iter().position(|v| !v.is_finite()) {
            return Err(Fault::StreamFailed(format!(
                "joint {} reads {}",
                i + 1,
                s.joints_deg[i]
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::RobotState;

    fn report(state: RobotState, received_at: Instant, sequence: u64) -> StampedState {
        StampedState {
            state,
            received_at,
            sequence,
        }
    }

    fn watchdog() -> Watchdog {
        Watchdog::new(Duration::from_millis(50), |_| "")
    }

    #[test]
    fn a_collision_is_a_stop() {
        let state = RobotState {
            collision: true,
            ..RobotState::default()
        };
        let fault = watchdog().check(&report(state, Instant::now(), 1), Instant::now());
        assert_eq!(fault, Err(Fault::Collision));
        assert!(Fault::Collision.to_string().contains("collision"));
        let with_code = RobotState {
            collision: true,
            main_code: 201,
            sub_code: 3,
            ..RobotState::default()
        };
        let fault = watchdog().check(&report(with_code, Instant::now(), 1), Instant::now());
        assert_eq!(
            fault,
            Err(Fault::Collision),
            "the cause is named, not its code"
        );
    }

    /// Frames that keep arriving on time but carry a controller clock that has stopped are
    /// old data: a stop once the clock has stood still longer than the deadline.
    #[test]
    fn frames_on_time_with_a_stopped_clock_are_stale() {
        let w = watchdog();
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let state = |clock: i64| RobotState {
            controller_clock_ms: Some(clock),
            ..RobotState::default()
        };
        // A moving clock, frames every 8 ms: fine.
        for k in 0..10u64 {
            let r = report(state(1000 + 8 * k as i64), at(8 * k), k);
            assert!(w.check(&r, at(8 * k)).is_ok());
        }
        // The clock stops at 1072 (the frame at 72 ms); frames still come every 8 ms.
        let mut stopped = None;
        for k in 10..30u64 {
            let r = report(state(1072), at(8 * k), k);
            if let Err(fault) = w.check(&r, at(8 * k)) {
                stopped = Some((8 * k, fault));
                break;
            }
        }
        let (when, fault) = stopped.expect("never stopped");
        assert!(matches!(fault, Fault::FrozenState { .. }), "{fault}");
        assert!((72 + 50..=72 + 58).contains(&when), "stopped at {when} ms");
        // Without the clock in the stream, nothing to judge.
        let r = report(RobotState::default(), at(400), 99);
        assert!(watchdog().check(&r, at(400)).is_ok());
    }
}
