//! [`GripperRamp`]: how an electric parallel gripper's controller moves the fingers after a
//! `MoveGripper`: the set point leaves from where the fingers are and moves towards the
//! commanded opening at the commanded speed. One implementation serves the twin's controller
//! model and training's `[control.gripper]`, so a policy learns the gripper it meets on the arm.
//! Openings are in % of the stroke (0 closed … 100 open), speeds in % of the stroke per second.

/// The set-point speed of the simulated fingers' own motion (% of the stroke per second): once
/// moving they open or close by 46 of their 90 mm in one 1/30 s control step (measured in
/// training episodes), so a gripper at full speed leaves their motion close to a jump of the
/// target, and at `s` % of full speed it takes 100/`s` times as long.
pub const FINGERS_FULL_SPEED_PERCENT_PER_S: f64 = 1500.0;

/// The gripper's set point (see the module documentation at the top of `control/gripper.rs`).
#[derive(Clone, Debug, PartialEq)]
pub struct GripperRamp {
    /// Commanded opening (%).
    target: f64,
    /// Where the fingers are sent now (%).
    setpoint: f64,
    /// % of the stroke per second.
    speed: f64,
}

impl GripperRamp {
    /// At rest at `opening` %.
    pub fn at(opening: f64) -> Self {
        let opening = opening.clamp(0.0, 100.0);
        Self {
            target: opening,
            setpoint: opening,
            speed: FINGERS_FULL_SPEED_PERCENT_PER_S,
        }
    }

    /// A move to `target` % at `speed` %/s from `fingers`, where the fingers are now: after a
    /// stall on an object the old set point had run ahead of them.
    pub fn command(&mut self, fingers: f64, target: f64, speed: f64) {
        self.setpoint = fingers.clamp(0.0, 100.0);
        self.target = target.clamp(0.0, 100.0);
        self.speed = speed.max(0.0);
    }

    /// Moves the set point on by `dt` seconds and returns it (%).
    pub fn advance(&mut self, dt: f64) -> f64 {
        let step = self.speed * dt.max(0.0);
        self.setpoint += (self.target - self.setpoint).clamp(-step, step);
        self.setpoint
    }

    /// The commanded opening (% of the stroke).
    pub fn target(&self) -> f64 {
        self.target
    }

    /// Where the fingers are sent now (% of the stroke), as of the last [`advance`](Self::advance).
    pub fn setpoint(&self) -> f64 {
        self.setpoint
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moves_at_its_speed_from_the_fingers_and_stops_at_the_target() {
        let mut g = GripperRamp::at(100.0);
        g.command(100.0, 0.0, 375.0);
        assert!((g.advance(0.1) - 62.5).abs() < 1e-9);
        assert_eq!(g.advance(1.0), 0.0, "stops at the target");
        // The next move leaves from the fingers (stalled at 40 %), not from the set point.
        g.command(40.0, 100.0, 1500.0);
        assert!((g.advance(0.02) - 70.0).abs() < 1e-9);
        assert_eq!(g.advance(-1.0), 70.0, "time never runs backwards");
        g.command(250.0, -3.0, 10.0);
        assert_eq!(
            (g.setpoint(), g.target()),
            (100.0, 0.0),
            "held to the stroke"
        );
    }
}
