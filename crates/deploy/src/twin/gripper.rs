//! The twin's gripper as the controller sees it: activation, a commanded position in % of the
//! stroke (0 closed … 100 open) reached at the command's speed (the [`GripperRamp`] training's
//! `[control.gripper]` moves the simulated fingers through), and "motion done" when the fingers
//! arrive, stall on an object or run out of the command's time.
//!
//! The command's force % is the fingers' squeezing force (the world turns it into the finger
//! drive's force limit). Fingers that stall short of a closing target hold an object: motion
//! done, the position short of the target, and the gripper's current (`gripper_current`, % in
//! the CNDE stream, the SDK's `GetGripperCurCurrent`) at the command's force %, the current a
//! drive pushing at its force limit draws. The vendor's stream has no "object held" flag; those
//! three together are how its gripper tells it. Otherwise the current reads 0.

use fairgrasp_sim::control::{FINGERS_FULL_SPEED_PERCENT_PER_S, GripperRamp};

/// The `MoveGripper` force % at which the fingers squeeze with the scene's `gripper.force_limit`
/// (the deployment loop's own setting, so that deployment meets the fingers training saw).
pub const NOMINAL_FORCE_PERCENT: f64 = 50.0;

/// Position error that counts as arrived (% of the stroke).
const ARRIVED_PERCENT: f64 = 1.0;
/// Movement smaller than this (%) over [`STALL_SECONDS`] is a stall (fingers on an object).
const PROGRESS_PERCENT: f64 = 0.3;
const STALL_SECONDS: f64 = 0.15;

/// The gripper state machine.
#[derive(Clone, Debug)]
pub struct Gripper {
    /// Activated (`ActGripper`).
    pub active: bool,
    /// Where the fingers are sent now, and the commanded position.
    ramp: GripperRamp,
    /// When the ramp was last advanced (s).
    ramped_at: f64,
    /// Measured position (%).
    pub position: f64,
    /// The latest command's motion is done: arrived, stalled or out of time.
    pub done: bool,
    /// Counts `MoveGripper` commands, so a blocking call can wait for its own.
    pub command: u64,
    commanded_at: f64,
    max_time: f64,
    /// Last time the fingers moved by more than [`PROGRESS_PERCENT`], and where they were.
    progress: (f64, f64),
    /// The squeezing force of the latest command (%).
    pub force_percent: f64,
    /// Stalled short of a closing target: an object is between the fingers.
    pub holding: bool,
}

impl Gripper {
    /// An open gripper, activated or not.
    pub fn new(active: bool) -> Self {
        Self {
            active,
            ramp: GripperRamp::at(100.0),
            ramped_at: 0.0,
            position: 100.0,
            done: true,
            command: 0,
            commanded_at: 0.0,
            max_time: f64::INFINITY,
            progress: (0.0, 100.0),
            force_percent: NOMINAL_FORCE_PERCENT,
            holding: false,
        }
    }

    /// Starts a move to `percent` (0…100) at `speed_percent` (1…100) of the full speed and
    /// `force_percent` of the force, that gives up after `max_time` s; returns its number.
    pub fn command(
        &mut self,
        now: f64,
        [percent, speed_percent, force_percent]: [f64; 3],
        max_time: f64,
    ) -> u64 {
        // At `s` % of full speed (the simulated fingers' own) a move takes 100/`s` times as
        // long, as the deployment's speed scale slows the arm.
        let speed = speed_percent.clamp(1.0, 100.0) / 100.0 * FINGERS_FULL_SPEED_PERCENT_PER_S;
        self.ramp.command(self.position, percent, speed);
        self.ramped_at = now;
        self.done = (self.position - self.ramp.target()).abs() < ARRIVED_PERCENT;
        self.commanded_at = now;
        self.max_time = max_time;
        self.progress = (now, self.position);
        self.force_percent = force_percent;
        self.holding = false;
        self.command += 1;
        self.command
    }

    /// The gripper's current (% of its rating): the force % while it holds, else 0.
    pub fn current_percent(&self) -> f64 {
        if self.holding {
            self.force_percent
        } else {
            0.0
        }
    }

    /// The position the fingers are sent to at `now` (%).
    pub fn setpoint(&mut self, now: f64) -> f64 {
        let dt = now - self.ramped_at;
        self.ramped_at = now;
        self.ramp.advance(dt)
    }

    /// Feeds the measured position (%).
    pub fn observe(&mut self, now: f64, position: f64) {
        self.position = position;
        let arrived = (position - self.ramp.target()).abs() < ARRIVED_PERCENT;
        if self.done {
            // An object that slips out lets the fingers close on.
            self.holding &= !arrived;
            return;
        }
        if (position - self.progress.1).abs() > PROGRESS_PERCENT {
            self.progress = (now, position);
        }
        let stalled = now - self.progress.0 > STALL_SECONDS;
        let timed_out = now - self.commanded_at > self.max_time;
        self.done = arrived || stalled || timed_out;
        self.holding = stalled && !arrived && position > self.ramp.target();
    }

    /// Sets the target to where the fingers are (a reset of the world put them there).
    pub fn hold_at(&mut self, position: f64) {
        self.position = position;
        self.ramp = GripperRamp::at(position);
        self.done = true;
        self.holding = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn done_on_arrival_on_stall_and_on_timeout() {
        let mut g = Gripper::new(true);
        g.command(0.0, [0.0, 100.0, 50.0], 10.0);
        assert!(!g.done);
        g.observe(0.05, 50.0);
        assert!(!g.done);
        g.observe(0.1, 0.5);
        assert!(g.done, "arrived");

        g.command(1.0, [100.0, 100.0, 50.0], 10.0);
        g.observe(1.05, 40.0);
        g.observe(1.1, 40.1);
        assert!(!g.done, "not yet stalled");
        g.observe(1.25, 40.1);
        assert!(g.done, "stalled on an object");

        g.command(2.0, [0.0, 100.0, 50.0], 0.2);
        for i in 1..=3 {
            g.observe(2.0 + i as f64 * 0.05, 40.0 - i as f64 * 5.0);
        }
        assert!(!g.done);
        g.observe(2.25, 20.0);
        assert!(g.done, "out of time");
    }

    #[test]
    fn the_set_point_moves_at_the_commanded_speed() {
        let mut g = Gripper::new(true);
        g.command(0.0, [0.0, 25.0, 50.0], 10.0);
        // A quarter of full speed: 375 %/s, so 37.5 % of the stroke in 0.1 s.
        let after = g.setpoint(0.1);
        assert!((after - 62.5).abs() < 1e-9, "{after}");
        assert_eq!(g.setpoint(1.0), 0.0, "stops at the target");
        // A new command ramps from where the fingers are, not from the old set point.
        g.observe(1.0, 40.0);
        g.command(1.0, [100.0, 100.0, 50.0], 10.0);
        let after = g.setpoint(1.02);
        assert!((after - 70.0).abs() < 1e-9, "{after}");
        // Out-of-range speeds are held to 1…100 %.
        g.command(2.0, [0.0, 0.0, 50.0], 10.0);
        assert!((g.setpoint(3.0) - (g.position - 15.0)).abs() < 1e-9);
    }
}
