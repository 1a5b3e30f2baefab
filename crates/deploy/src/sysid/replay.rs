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

/// The simulated arm a recording is replayed through.
#[derive(Clone, Debug)]
pub struct ArmSim {
    /// An arm task of the env registry (its scene: the FR5 as trained).
    pub env_id: String,
    pub env_config: toml::Table,
}

impl ArmSim {
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
        let until = recording
            .state_times()
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
        let t0 = first.t - LEAD_S;
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
