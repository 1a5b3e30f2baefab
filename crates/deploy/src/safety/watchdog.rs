//! [`Watchdog`]: is the controller's newest state fit to act on?

use super::Fault;
use crate::robot::StampedState;
use std::time::{Duration, Instant};

/// Judges each state report: fresh enough, no fault code, no e-stop, no safety stop.
#[derive(Clone, Debug)]
pub struct Watchdog {
    deadline: Duration,
    meaning: fn(i64) -> &'static str,
}

impl Watchdog {
    /// `meaning` turns a controller error code into words (the protocol's table).
    pub fn new(deadline: Duration, meaning: fn(i64) -> &'static str) -> Self {
        Self { deadline, meaning }
    }

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
        if s.main_code != 0 {
            return Err(Fault::ControllerFault {
                main_code: s.main_code,
                sub_code: s.sub_code,
                meaning: (self.meaning)(s.main_code as i64).to_string(),
            });
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
