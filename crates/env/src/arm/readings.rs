//! One observation path: the policy's [`ArmState`] built from what a controller reports, the
//! same code in training and on the arm.
//!
//! A FAIRINO controller reports joint angles and speeds in degrees, the gripper's position as an
//! integer percentage of its stroke, and nothing about finger contacts; the object's pose comes
//! from a feed that is up to one period old. The deployment loop turns those readings into the
//! policy's state with a [`StateEstimator`]; with `[readings] enabled = true` training
//! synthesises the same readings from the simulator every control step and goes through the
//! same estimator, so the actor never sees a value (true pad contacts, an exact finger opening,
//! a current object pose) that the arm cannot give it. Rewards and success stay on the true
//! state.

use crate::arm::state::{ArmState, ObjectReading};
use crate::config::{check_non_negative, check_range};
use crate::error::Result;
use fairgrasp_sim::kinematics::SerialChain;
use fairgrasp_sim::rapier3d::na::{Isometry3, Vector3};
use serde::{Deserialize, Serialize};

/// The `[readings]` settings: build the policy's observation from synthesized controller
/// readings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReadingsConfig {
    /// Off: the observation is read from the simulator's true state (the default, and how
    /// every model before this option was trained).
    pub enabled: bool,
    /// The object pose feed's rate (Hz, the simulator's time). Each control step sees the pose
    /// as it was a uniformly drawn age of up to one feed period earlier; 0 shows the current
    /// pose.
    pub object_feed_hz: f32,
    /// How old the controller's readings are when the policy acts, drawn each control step
    /// (ms of the simulator's time, uniform, rounded to physics substeps, less than one
    /// control step): the state stream's period, the reply latency before a set point acts,
    /// and the drives' own delay. At speed scale s they are s times as long in the policy's
    /// time, as on the arm. `[0, 0]`: read at the step's end.
    pub state_age_ms: [f32; 2],
    /// Report, in `info.privileged`, what only the simulator knows, for an asymmetric critic
    /// (`ppo.privileged_critic`): the task's observation of the true state (true contacts,
    /// velocities and object pose, no noise, no age) and the episode's speed scale. The
    /// policy never reads it.
    pub privileged: bool,
}

impl Default for ReadingsConfig {
    fn default() -> Self {
        // The twin publishes the object's pose at 30 Hz.
        Self {
            enabled: false,
            object_feed_hz: 30.0,
            state_age_ms: [0.0, 0.0],
            privileged: false,
        }
    }
}

impl ReadingsConfig {
    /// Checks the ranges; errors name the key (`readings.…`).
    pub fn validate(&self) -> Result<()> {
        check_non_negative("readings.object_feed_hz", self.object_feed_hz)?;
        check_range("readings.state_age_ms", self.state_age_ms, 0.0, 1000.0)?;
        Ok(())
    }

    /// The largest age of an object pose (s): one feed period, or none.
    pub fn max_object_age(&self) -> f64 {
        if self.object_feed_hz > 0.0 {
            1.0 / self.object_feed_hz as f64
        } else {
            0.0
        }
    }
}

/// What the controller reports at one instant, in the simulator's joint frame (after the
/// calibration on a real arm): the controller's own units.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ControllerReading {
    /// Joint angles (deg).
    pub joints_deg: Vec<f64>,
    /// Joint speeds (deg/s), in the policy's time (on the arm: divided by the speed scale).
    pub joint_speeds_deg: Vec<f64>,
    /// Gripper position, % of the stroke open (0 closed … 100 open).
    pub gripper_percent: u8,
}

impl ControllerReading {
    /// What a controller reports for joints `q`, speeds `qd` (rad, rad/s) and a finger opening
    /// (m, of `max_opening`).
    pub fn synthesize(q: &[f32], qd: &[f32], opening: f32, max_opening: f32) -> Self {
        Self {
            joints_deg: q.iter().map(|&v| (v as f64).to_degrees()).collect(),
            joint_speeds_deg: qd.iter().map(|&v| (v as f64).to_degrees()).collect(),
            gripper_percent: gripper_percent(opening, max_opening),
        }
    }
}

/// The gripper's position as a controller reports it: the opening in whole percent of the
/// stroke.
pub fn gripper_percent(opening: f32, max_opening: f32) -> u8 {
    gripper_percent_of((opening / max_opening) as f64 * 100.0)
}

/// A position in percent of the stroke, rounded to the controller's whole percent.
pub fn gripper_percent_of(percent: f64) -> u8 {
    percent.round().clamp(0.0, 100.0) as u8
}

/// Gripper position (% open) below which a closed gripper that has stopped is taken to hold
/// nothing: fully closed reads 0–4 % (finger jitter), and the grasp rule asks for more than
/// 5 mm of the 90 mm stroke.
const HOLDING_MIN_PERCENT: u8 = 6;
/// How far (% of the stroke) the fingers must have closed before a stop counts as a grasp, so
/// the first reading after a close command (fingers not yet moving) is not one.
const HOLDING_MIN_TRAVEL: u8 = 5;
/// Fingers this close (m) to the object's narrowest or widest extent across count as touching
/// it.
const WIDTH_TOLERANCE: f32 = 0.003;

/// What the estimator needs to know of the world that no reading gives: the table, the
/// gripper's stroke, the object's size and resting height, and the chain the TCP is computed
/// by. Taken from the env's nominal (reset, unrandomised) state.
#[derive(Clone, Debug)]
pub struct EstimatorFacts {
    /// The kinematic chain from the arm base to the TCP.
    pub chain: SerialChain,
    /// Height of the table top (m, base frame z).
    pub table_z: f64,
    /// Largest distance between the finger pads (m): 100 % of the stroke.
    pub gripper_max_opening: f32,
    /// Object 0 at rest: its half extents and resting height.
    pub object: ObjectReading,
}

impl EstimatorFacts {
    /// The facts of the nominal state `nominal` (its object 0), with `chain` for the TCP.
    pub fn new(chain: SerialChain, nominal: &ArmState) -> Self {
        Self {
            chain,
            table_z: nominal.table_z,
            gripper_max_opening: nominal.gripper_max_opening,
            object: nominal.objects[0].clone(),
        }
    }
}

/// Builds the policy's [`ArmState`]s from successive readings (see the [module](self)).
///
/// - joints and speeds as read; the TCP by the policy's kinematic chain from the read joints;
/// - the gripper opening from its whole percent;
/// - velocities of the TCP and the object by differences over the policy time between readings;
/// - pad contacts, which no controller reports, inferred: a closing gripper whose fingers have
///   travelled and then stopped between two readings, or whose opening is the object's width,
///   holds it (both pads). The gripper's own "motion done" comes only after its stall timeout
///   (150 ms on the twin), later than the simulator's pads touch, so it is not used.
#[derive(Clone, Debug, Default)]
pub struct StateEstimator {
    previous: Option<(Vector3<f64>, Vector3<f64>)>,
    /// The gripper position (%) when the close command was first seen.
    closing_from: Option<u8>,
    last_gripper: Option<u8>,
}

impl StateEstimator {
    /// An estimator that has seen no reading yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// The state from a reading, the object's pose (base frame) and whether the gripper is
    /// commanded closed; `dt` is the policy time since the previous reading (s).
    pub fn estimate(
        &mut self,
        facts: &EstimatorFacts,
        reading: &ControllerReading,
        object_pose: Isometry3<f64>,
        gripper_closing: bool,
        dt: f64,
    ) -> ArmState {
        let q: Vec<f32> = (reading.joints_deg.iter())
            .map(|&v| v.to_radians() as f32)
            .collect();
        let qd: Vec<f32> = (reading.joint_speeds_deg.iter())
            .map(|&v| v.to_radians() as f32)
            .collect();
        let q64: Vec<f64> = q.iter().map(|&v| v as f64).collect();
        let tcp: Isometry3<f64> = facts.chain.forward(&q64);
        let (tcp_p, obj_p) = (tcp.translation.vector, object_pose.translation.vector);
        let (tcp_linvel, obj_linvel) = match self.previous {
            Some((tp, op)) if dt > 1e-4 => ((tcp_p - tp) / dt, (obj_p - op) / dt),
            _ => (Vector3::zeros(), Vector3::zeros()),
        };
        self.previous = Some((tcp_p, obj_p));
        let max_opening = facts.gripper_max_opening;
        let position = reading.gripper_percent.min(100);
        let opening = max_opening * position as f32 / 100.0;
        let from = if gripper_closing {
            // The reading before the close command was seen: the fingers can cover most of
            // the stroke within one control step.
            *self
                .closing_from
                .get_or_insert(self.last_gripper.unwrap_or(position))
        } else {
            self.closing_from = None;
            position
        };
        let travelled = position.saturating_add(HOLDING_MIN_TRAVEL) <= from;
        let stopped = self.last_gripper.is_some_and(|last| position >= last);
        self.last_gripper = Some(position);
        // Between the object's narrowest and widest extent across the table, within the
        // tolerance: touching it. Below that band the fingers passed it: nothing between them.
        let [a, b, _] = facts.object.half_extents;
        let at_width = (2.0 * a.min(b) - WIDTH_TOLERANCE..=2.0 * a.max(b) + WIDTH_TOLERANCE)
            .contains(&opening);
        let holding = gripper_closing
            && travelled
            && position >= HOLDING_MIN_PERCENT
            && (stopped || at_width);
        let mut object = facts.object.clone();
        object.pose = object_pose;
        object.linvel = obj_linvel;
        object.pad_contacts = [holding, holding];
        ArmState {
            q,
            qd,
            tcp,
            tcp_linvel,
            gripper_opening: opening,
            gripper_max_opening: max_opening,
            gripper_closing,
            table_z: facts.table_z,
            objects: vec![object],
        }
    }
}

/// A pose `age` seconds before `now`, by linear interpolation from `before` (`period` seconds
/// earlier): what a feed that sampled it then shows.
pub fn aged_pose(
    before: &Isometry3<f64>,
    now: &Isometry3<f64>,
    age: f64,
    period: f64,
) -> Isometry3<f64> {
    if age <= 0.0 || period <= 0.0 {
        return *now;
    }
    let t = (1.0 - age / period).clamp(0.0, 1.0);
    before.lerp_slerp(now, t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arm::ArmEnv;
    use crate::tasks::grasp::{Grasp, GraspConfig};
    use crate::{Env, GraspEnv};

    fn facts() -> EstimatorFacts {
        let mut env: ArmEnv<Grasp> = GraspEnv::new(GraspConfig::default()).unwrap();
        env.reset(Some(0)).unwrap();
        let chain = SerialChain::new(&env.scene().robot().model, "tcp").unwrap();
        EstimatorFacts::new(chain, env.state().unwrap())
    }

    fn cube() -> Isometry3<f64> {
        Isometry3::translation(0.45, 0.0, 0.025)
    }

    /// The pads of the estimated state while the gripper, commanded closed, reads `positions`
    /// (% open).
    fn pads(positions: &[u8]) -> Vec<bool> {
        let facts = facts();
        let mut estimator = StateEstimator::new();
        let home = vec![0.0; 6];
        positions
            .iter()
            .map(|&position| {
                let reading = ControllerReading {
                    joints_deg: home.clone(),
                    joint_speeds_deg: home.clone(),
                    gripper_percent: position,
                };
                let s = estimator.estimate(&facts, &reading, cube(), true, 1.0 / 30.0);
                s.objects[0].pad_contacts[0]
            })
            .collect()
    }

    #[test]
    fn fingers_stopped_partway_hold_at_once() {
        // Closing from open: moving, moving, stopped at 88 % (a cube turned across the
        // fingers), still stopped: held from the second stopped reading.
        assert_eq!(
            pads(&[100, 95, 90, 88, 88]),
            [false, false, false, false, true]
        );
        // Fingers at the 5 cm cube's width (56 % of 9 cm): touching at once.
        assert_eq!(pads(&[100, 80, 58, 58]), [false, false, true, true]);
        // Even when the first reading after the command finds them there already.
        assert_eq!(pads(&[100, 58]), [false, true]);
    }

    #[test]
    fn an_unmoved_or_fully_closed_gripper_is_not_a_grasp() {
        // Not yet moving right after the close command.
        assert_eq!(pads(&[100, 100]), [false, false]);
        // Closed on nothing, or passing well inside the object's width while still moving.
        assert_eq!(pads(&[100, 70, 0, 0]), [false; 4]);
        assert_eq!(pads(&[100, 30, 11]), [false; 3]);
        // Fully closed reads a few percent (finger jitter): stopped there, nothing is held.
        assert_eq!(pads(&[100, 40, 4, 4]), [false; 4]);
    }

    #[test]
    fn velocities_are_differences_over_the_given_policy_time() {
        let facts = facts();
        let mut e = StateEstimator::new();
        let reading = ControllerReading {
            joints_deg: vec![0.0; 6],
            joint_speeds_deg: vec![10.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            gripper_percent: 100,
        };
        let first = e.estimate(&facts, &reading, cube(), false, 0.0);
        assert_eq!(first.objects[0].linvel, Vector3::zeros());
        let moved = Isometry3::translation(0.451, 0.0, 0.025);
        let s = e.estimate(&facts, &reading, moved, false, 0.1);
        assert!((s.qd[0] - 10f32.to_radians()).abs() < 1e-6);
        assert!((s.objects[0].linvel.x - 0.01).abs() < 1e-9);
    }

    #[test]
    fn the_gripper_reads_in_whole_percent() {
        assert_eq!(gripper_percent(0.045, 0.09), 50);
        assert_eq!(gripper_percent(0.0454, 0.09), 50);
        assert_eq!(gripper_percent(0.0456, 0.09), 51);
        assert_eq!(gripper_percent(0.1, 0.09), 100);
        assert_eq!(gripper_percent(-0.001, 0.09), 0);
    }

    #[test]
    fn an_aged_pose_lies_between_the_two_samples() {
        let (a, b) = (Isometry3::translation(0.0, 0.0, 0.0), cube());
        assert_eq!(aged_pose(&a, &b, 0.0, 0.1), b);
        let half = aged_pose(&a, &b, 0.05, 0.1);
        assert!((half.translation.x - 0.225).abs() < 1e-12);
        assert_eq!(aged_pose(&a, &b, 0.5, 0.1), a);
    }
}
