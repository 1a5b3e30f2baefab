//! The model in the loop: a recording's set points replayed through the training simulator's
//! arm (the twin's [`World`], whose joints are the env's PD joints with the drives' integral
//! action), optionally through a drive model first, on the simulator's own physics step.

use super::fit::Uniform;
use super::record::Recording;
use crate::error::{DeployError, Result};
use crate::twin::controller::Setpoint;
use crate::twin::faults::TrackingModel;
use crate::twin::motion::{Drives, ServoStep};
use crate::twin::world::World;

/// The replay's fingers stay open at the force the simulated drive has of its own (the twin's
/// 50 %): no object is held, so only the arm's motion matters.
const OPEN_GRIPPER_FORCE_PERCENT: f64 = 50.0;

/// How long the replayed arm rests at the start pose first (s): the drives' integral action
/// learns the sag, as it had on the arm before the recording.
const SETTLE_S: f64 = 1.0;
/// The replay starts this long before the first set point (s).
const LEAD_S: f64 = 0.05;

/// Where the stream's frames fall on a grid of step `dt` (s, in `[0, dt)`): the circular mean of
/// their times modulo `dt`. A twin takes its frames on its physics step, and a replay stepped on
/// the same grid applies each set point on the same step and is read without interpolating
/// (on another grid the fit's best split of delay and lag moved by up to 19 % with exact
/// clocks and no noise). A real controller's frames fall anywhere on it, and any phase serves.
fn grid_phase(times: &[f64], dt: f64) -> f64 {
    let (mut sin, mut cos) = (0.0, 0.0);
    for &t in times {
        let angle = std::f64::consts::TAU * (t / dt).fract();
        sin += angle.sin();
        cos += angle.cos();
    }
    let phase = sin.atan2(cos) / std::f64::consts::TAU * dt;
    if phase.is_finite() {
        phase.rem_euclid(dt)
    } else {
        0.0
    }
}

/// The simulated arm a recording is replayed through.
#[derive(Clone, Debug)]
pub struct ArmSim {
    /// An arm task of the env registry (its scene: the FR5 as trained).
    pub env_id: String,
    /// The env's configuration table (empty: its defaults).
    pub env_config: toml::Table,
}

impl ArmSim {
    /// `env_id` with its default configuration.
    pub fn new(env_id: &str) -> Self {
        Self {
            env_id: env_id.to_string(),
            env_config: toml::Table::new(),
        }
    }

    /// The joints (deg) the simulator gives for the recording's set points, each passed through
    /// `drives` first: one signal per joint on the physics step, from just before the first
    /// set point to the last reading.
    pub fn replay(&self, recording: &Recording, drives: &TrackingModel) -> Result<[Uniform; 6]> {
        let commands = &recording.commands;
        let first = commands.first().ok_or_else(|| {
            DeployError::config("system identification", "the recording has no set point")
        })?;
        let times = recording.state_times();
        let until = times
            .last()
            .copied()
            .unwrap_or(first.t)
            .max(commands.last().map_or(first.t, |c| c.t + c.cmd_t));
        let mut world = World::new(&self.env_id, &self.env_config, 0)?;
        let dt = world.dt();
        let start = recording.start_deg;
        world.place_arm(&start)?;
        let hold = Setpoint {
            joints_deg: start,
            gripper_percent: 100.0,
            gripper_force_percent: OPEN_GRIPPER_FORCE_PERCENT,
        };
        for _ in 0..(SETTLE_S / dt).round() as usize {
            world.step(&hold)?;
        }
        let phase = grid_phase(&times, dt);
        let t0 = phase + ((first.t - LEAD_S - phase) / dt).floor() * dt;
        let steps = ((until - t0) / dt).ceil().max(1.0) as usize + 1;
        // The controller's interpolation of each ServoJ: a straight line from where its set
        // point is when the command arrives to the target, over cmdT.
        let mut step = ServoStep {
            from: start,
            to: start,
            start: t0,
            duration: 0.0,
        };
        let mut next = 0;
        let mut follower = Drives::new(start, t0);
        let mut out: [Vec<f64>; 6] = std::array::from_fn(|_| Vec::with_capacity(steps));
        for k in 0..steps {
            let t = t0 + k as f64 * dt;
            while let Some(c) = commands.get(next).filter(|c| c.t <= t) {
                step = ServoStep {
                    from: step.at(c.t),
                    to: c.joints_deg,
                    start: c.t,
                    duration: c.cmd_t,
                };
                next += 1;
            }
            let set_point = follower.follow(drives, t, step.at(t), t);
            world.step(&Setpoint {
                joints_deg: set_point,
                gripper_percent: 100.0,
                gripper_force_percent: OPEN_GRIPPER_FORCE_PERCENT,
            })?;
            let q = world.measure().joints_deg;
            for j in 0..6 {
                out[j].push(q[j]);
            }
        }
        Ok(out.map(|values| Uniform { t0, dt, values }))
    }
}

#[cfg(test)]
mod tests {
    use super::grid_phase;

    #[test]
    fn the_frames_grid_is_found_through_millisecond_clocks() {
        let dt = 1.0 / 240.0;
        for phase in [0.0, 0.0013, 0.004] {
            // Frames every second step, their clocks rounded to the millisecond.
            let times: Vec<f64> = (0..2000)
                .map(|k| ((100.0 + phase + 2.0 * k as f64 * dt) * 1e3).round() / 1e3)
                .collect();
            let found = grid_phase(&times, dt);
            let off = (found - phase + 0.5 * dt).rem_euclid(dt) - 0.5 * dt;
            assert!(off.abs() < 5e-5, "phase {phase} s, found {found} s");
        }
        assert_eq!(grid_phase(&[], dt), 0.0);
    }
}
