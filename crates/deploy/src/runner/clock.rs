//! [`ServoClock`]: the servo ticks' fixed schedule. Tick `n` (from 0) is due at `start + n ×
//! period`, whatever the replies did: a slow reply does not move the ticks after it. When
//! sending falls behind, the next send covers every tick due by then (the set point that far
//! along the ramp, over a cmdT of that many periods) up to the longest cmdT the controller
//! takes ([`MAX_CMD_T`]); beyond that the schedule gives up the lost time rather than move the
//! arm faster than its caps.

use std::time::{Duration, Instant};

/// The longest cmdT a FAIRINO controller accepts in ServoJ (s).
pub const MAX_CMD_T: f64 = 0.016;

/// The servo ticks' fixed schedule: tick `n` is due at `start + n × period`.
#[derive(Clone, Debug)]
pub struct ServoClock {
    start: Instant,
    period: Duration,
    /// Ticks handed out so far.
    taken: u64,
    /// Ticks given up because sending fell too far behind.
    slipped: u64,
    /// The most ticks one send may cover (their span within [`MAX_CMD_T`]).
    max_per_send: u64,
}

impl ServoClock {
    /// A schedule whose tick 0 is due at `start`.
    pub fn new(start: Instant, period: Duration) -> Self {
        let max_per_send = (MAX_CMD_T / period.as_secs_f64() + 1e-9).floor().max(1.0) as u64;
        Self {
            start,
            period,
            taken: 0,
            slipped: 0,
            max_per_send,
        }
    }

    /// Time between ticks.
    pub fn period(&self) -> Duration {
        self.period
    }

    /// Ticks handed out so far.
    pub fn taken(&self) -> u64 {
        self.taken
    }

    /// Ticks given up because sending fell further behind than one send may cover.
    pub fn slipped(&self) -> u64 {
        self.slipped
    }

    /// When the next tick is due.
    pub fn next_due(&self) -> Instant {
        self.start + self.period * (self.taken + self.slipped) as u32
    }

    /// Takes every tick due at `now` (at least one), no more than one send may cover and never
    /// past tick `until` (exclusive); returns how many. Call it once the next tick is due.
    pub fn take_due(&mut self, now: Instant, until: u64) -> u32 {
        let elapsed = now.saturating_duration_since(self.start);
        let due = (elapsed.as_nanos() / self.period.as_nanos().max(1)) as u64 + 1;
        let mut n = due.saturating_sub(self.taken + self.slipped).max(1);
        if n > self.max_per_send {
            self.slipped += n - self.max_per_send;
            n = self.max_per_send;
        }
        let n = n.min(until.saturating_sub(self.taken)).max(1);
        self.taken += n;
        n as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn late_sends_cover_the_ticks_they_missed_without_moving_later_ones() {
        let t0 = Instant::now();
        let ms = Duration::from_millis;
        let mut clock = ServoClock::new(t0, ms(8));
        assert_eq!(clock.take_due(t0, 100), 1);
        // The next send 10 ms later: tick 1 (due at 8 ms) only.
        assert_eq!(clock.take_due(t0 + ms(10), 100), 1);
        assert_eq!(clock.next_due(), t0 + ms(16));
        // At 20 ms tick 2 is due; at 40 ms ticks 3, 4 and 5: two taken, one given up.
        assert_eq!(clock.take_due(t0 + ms(20), 100), 1);
        assert_eq!(clock.take_due(t0 + ms(40), 100), 2);
        assert_eq!(clock.slipped(), 1);
        assert_eq!(clock.next_due(), t0 + ms(48));
        // Never past the control step's last tick: two are due at 60 ms, one is left before 6.
        assert_eq!(clock.take_due(t0 + ms(60), 6), 1);
        assert_eq!(clock.taken(), 6);
    }
}
