//! The drives between a controller's set point and the joints: each joint's set point arrives
//! after a pure delay and is followed through a first-order lag. The twin's controller model
//! and training's `[control.drives]` both drive their joints through it, with the delays and
//! lags `fairgrasp sysid` identifies on the arm.

use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// One joint drive's tracking: the set point reaches the motor after a pure delay, then
/// through a first-order lag of time constant `tau_ms`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JointTracking {
    /// Pure delay before the set point reaches the drive (ms); 0 for none.
    pub delay_ms: f64,
    /// Time constant of the first-order lag (ms); 0 for none.
    pub tau_ms: f64,
}

/// History kept beyond the longest delay (s).
const HISTORY_MARGIN: f64 = 0.05;

/// `N` drives following their set points (any unit; seconds).
#[derive(Clone, Debug)]
pub struct DriveFilter<const N: usize> {
    /// The controller's set points by time, for the delay.
    history: VecDeque<(f64, [f64; N])>,
    output: [f64; N],
    time: f64,
}

impl<const N: usize> DriveFilter<N> {
    /// Drives at rest at `q` at time `now`.
    pub fn new(q: [f64; N], now: f64) -> Self {
        Self {
            history: VecDeque::from([(now, q)]),
            output: q,
            time: now,
        }
    }

    /// The drives' set points at `now`, given the controller's set point `command` at `at`
    /// (linear between the set points given).
    pub fn follow(
        &mut self,
        model: &[JointTracking; N],
        at: f64,
        command: [f64; N],
        now: f64,
    ) -> [f64; N] {
        if self.history.back().is_none_or(|(t, _)| at > *t) {
            self.history.push_back((at, command));
        }
        if model.iter().all(|d| *d == JointTracking::default()) {
            self.history.clear();
            self.history.push_back((at, command));
            self.output = command;
            self.time = self.time.max(now);
            return command;
        }
        let dt = now - self.time;
        if dt > 0.0 {
            for (j, drive) in model.iter().enumerate() {
                let delay = drive.delay_ms / 1e3;
                let u0 = self.at(self.time - delay)[j];
                let u1 = self.at(now - delay)[j];
                let tau = drive.tau_ms / 1e3;
                // Exact over the step for an input linear between its ends.
                self.output[j] = if tau > 0.0 {
                    let slope = (u1 - u0) / dt;
                    let decay = (-dt / tau).exp();
                    u1 - slope * tau + (self.output[j] - u0 + slope * tau) * decay
                } else {
                    u1
                };
            }
            self.time = now;
            let longest = model.iter().fold(0.0_f64, |m, t| m.max(t.delay_ms / 1e3));
            let keep_from = now - longest - HISTORY_MARGIN;
            while self.history.len() > 2 && self.history[1].0 < keep_from {
                self.history.pop_front();
            }
        }
        self.output
    }

    /// The controller's set point at time `t`, linear between the ones recorded.
    fn at(&self, t: f64) -> [f64; N] {
        let Some(&(first_t, first)) = self.history.front() else {
            return self.output;
        };
        if t <= first_t {
            return first;
        }
        for ((t0, q0), (t1, q1)) in self.history.iter().zip(self.history.iter().skip(1)) {
            if t <= *t1 {
                let s = (t - t0) / (t1 - t0);
                return std::array::from_fn(|j| q0[j] + (q1[j] - q0[j]) * s);
            }
        }
        self.history.back().map_or(self.output, |(_, q)| *q)
    }
}

/// A drive's integral action, as an offset added to the set points the simulated joints follow.
///
/// The simulated joints are PD-controlled without gravity compensation, so they sag a few
/// tenths of a degree below their targets; a real drive's integral action removes that, and so
/// it also pushes harder the longer a joint is held off its set point (on the table, on an
/// object). The term is slow, learnt only while the set point is nearly still, and bounded.
/// The twin's world and training's `[control.drives]` both apply it. Radians and seconds.
#[derive(Clone, Debug)]
pub struct DriveIntegral<const N: usize> {
    bias: [f64; N],
    /// The set point of the step under way (given to [`Self::drive`], not yet learnt from).
    driving: Option<[f64; N]>,
    /// The set point of the last step learnt from.
    last: Option<[f64; N]>,
}

impl<const N: usize> Default for DriveIntegral<N> {
    fn default() -> Self {
        Self {
            bias: [0.0; N],
            driving: None,
            last: None,
        }
    }
}

impl<const N: usize> DriveIntegral<N> {
    /// Integral gain (1/s).
    pub const GAIN: f64 = 4.0;
    /// Largest correction (0.5°).
    pub const MAX_BIAS: f64 = 0.5 * std::f64::consts::PI / 180.0;
    /// The term learns only while the set point moves slower than this (5°/s).
    pub const LEARN_SPEED: f64 = 5.0 * std::f64::consts::PI / 180.0;

    /// No correction yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// The next physics step's joint targets for `set_point`: the set point plus the
    /// correction.
    pub fn drive(&mut self, set_point: [f64; N]) -> [f64; N] {
        self.driving = Some(set_point);
        std::array::from_fn(|j| set_point[j] + self.bias[j])
    }

    /// Learns from the step [`Self::drive`] began, `dt` long, which ended with the joints at
    /// `measured` (the scene's arm positions; nothing before the first step).
    pub fn learn(&mut self, measured: &[f32], dt: f64) {
        let Some(set_point) = self.driving.take() else {
            return;
        };
        let still = self.last.is_some_and(|last| {
            (last.iter().zip(&set_point)).all(|(a, b)| (a - b).abs() < Self::LEARN_SPEED * dt)
        });
        if still {
            for (j, (bias, sp)) in self.bias.iter_mut().zip(set_point).enumerate() {
                let q = measured.get(j).map_or(0.0, |&v| v as f64);
                *bias = (*bias + Self::GAIN * (sp - q) * dt).clamp(-Self::MAX_BIAS, Self::MAX_BIAS);
            }
        }
        self.last = Some(set_point);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_arrives_after_the_delay_then_lags() {
        let model = [JointTracking {
            delay_ms: 10.0,
            tau_ms: 20.0,
        }];
        let mut f = DriveFilter::new([0.0], 0.0);
        let dt = 0.001;
        let mut out = Vec::new();
        // The set point steps to 1 at 1 ms (linear from 0 at 0 s).
        f.follow(&model, 0.0, [0.0], 0.0);
        for k in 1..=100 {
            let t = k as f64 * dt;
            out.push(f.follow(&model, 0.001, [1.0], t)[0]);
        }
        // Nothing before the delay; then 1 - exp(-(t - 10 ms - ramp) / 20 ms).
        assert!(out[9].abs() < 1e-12, "{}", out[9]);
        let at_50ms = out[49];
        let expected = 1.0 - (-(0.050 - 0.011) / 0.020f64).exp();
        assert!((at_50ms - expected).abs() < 0.02, "{at_50ms} vs {expected}");
        assert!(out.windows(2).all(|w| w[1] >= w[0]));
    }

    #[test]
    fn no_tracking_is_the_set_point() {
        let model = [JointTracking::default(); 2];
        let mut f = DriveFilter::new([0.0, 1.0], 0.0);
        assert_eq!(f.follow(&model, 0.004, [0.5, -1.0], 0.004), [0.5, -1.0]);
    }

    #[test]
    fn the_integral_closes_a_steady_error_while_still_and_is_bounded() {
        let mut i = DriveIntegral::<1>::new();
        let dt = 0.001;
        // A joint that sags 0.1° below a still set point: the correction grows towards it.
        let sag = 0.1f64.to_radians();
        let mut target = 0.0;
        for _ in 0..2000 {
            target = i.drive([0.0])[0];
            i.learn(&[(target - sag) as f32], dt);
        }
        assert!((target - sag).abs() < 0.01 * sag, "{:?}", i.bias);
        // Held far off (a joint pressed against the table), it stops at its bound.
        for _ in 0..5000 {
            i.drive([0.0]);
            i.learn(&[-0.1], dt);
        }
        assert_eq!(i.drive([0.0]), [DriveIntegral::<1>::MAX_BIAS]);
        // A moving set point teaches nothing, nor does a step never driven.
        let mut moving = DriveIntegral::<1>::new();
        for k in 0..1000 {
            let sp = k as f64 * 0.2 * dt;
            moving.drive([sp]);
            moving.learn(&[(sp - 0.1) as f32], dt);
            moving.learn(&[-1.0], dt);
        }
        assert_eq!(moving.drive([0.0]), [0.0]);
    }
}
