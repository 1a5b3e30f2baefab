//! A scripted top-down pick, and the primitive of the grasp task's success rule: the env's
//! grasp task configures a [`SuccessRule`] from its `[task]` settings and judges its states by
//! it, so the scripted pick, training, the twin and the deployment loop apply one rule.
//!
//! The script: open, move above an object with the fingers across its narrowest width, descend,
//! close, lift, hold. It drives the arm only through joint position targets (what a policy will do), so
//! its success shows the scene can be grasped with the controls the environment exposes. A failed
//! pick says why ([`PickFailure`]).

use crate::error::{Result, SimError};
use crate::scene::Scene;
use rapier3d::na::{Isometry3, Point3, Vector3};
use std::cell::Cell;
use std::collections::BTreeMap;
use std::fmt;

/// The grasp task's success rule: gripper closed on the object, object lifted, object centred
/// in the gripper, all held for a number of consecutive control steps. The defaults are the
/// grasp task's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SuccessRule {
    /// Lift of the object's centre above its resting height (m).
    pub min_lift: f64,
    /// Largest distance between the object's centre and the TCP (m).
    pub max_offset: f64,
    /// Consecutive control steps the conditions must hold.
    pub hold_steps: u32,
}

impl Default for SuccessRule {
    fn default() -> Self {
        Self {
            min_lift: 0.05,
            max_offset: 0.08,
            hold_steps: 10,
        }
    }
}

/// The smallest opening at which closed fingers are stopped by an object rather than by each
/// other (m).
pub const MIN_HELD_OPENING: f32 = 0.005;

/// Whether the gripper holds an object: commanded closed (`closing`), both pads touching it,
/// and the fingers stopped by it (`opening` above [`MIN_HELD_OPENING`]).
pub fn closed_on_object(closing: bool, pad_contacts: [bool; 2], opening: f32) -> bool {
    closing && pad_contacts[0] && pad_contacts[1] && opening > MIN_HELD_OPENING
}

/// What the success rule sees at one control step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GraspStatus {
    /// The gripper holds the object ([`closed_on_object`]).
    pub closed_on_object: bool,
    /// Object centre height above its resting height (m).
    pub lift: f64,
    /// Distance between the object centre and the TCP (m).
    pub offset: f64,
}

impl GraspStatus {
    /// Reads the scene about object `object` (its index).
    pub fn of(scene: &Scene, object: usize) -> Self {
        let closed_on_object = closed_on_object(
            scene.gripper_commanded_closed(),
            scene.finger_contacts(object),
            scene.gripper_opening(),
        );
        let centre = scene.object_state(object).pose.translation.vector;
        let tcp = scene.tcp_pose().translation.vector;
        Self {
            closed_on_object,
            lift: centre.z - scene.object_rest_height(object),
            offset: (centre - tcp).norm(),
        }
    }

    /// Whether this step satisfies every condition of `rule`.
    pub fn satisfies(&self, rule: &SuccessRule) -> bool {
        self.closed_on_object && self.lift > rule.min_lift && self.offset < rule.max_offset
    }
}

/// Counts consecutive control steps that satisfy the rule.
#[derive(Clone, Debug, Default)]
pub struct SuccessTracker {
    /// The rule each step is judged by.
    pub rule: SuccessRule,
    consecutive: u32,
}

impl SuccessTracker {
    /// A tracker for `rule` with no step counted yet.
    pub fn new(rule: SuccessRule) -> Self {
        Self {
            rule,
            consecutive: 0,
        }
    }

    /// Feeds one control step; returns whether the task is now achieved.
    pub fn update(&mut self, status: &GraspStatus) -> bool {
        if status.satisfies(&self.rule) {
            self.consecutive += 1;
        } else {
            self.consecutive = 0;
        }
        self.succeeded()
    }

    /// Whether the rule holds for at least `rule.hold_steps` consecutive steps, up to the last
    /// step fed.
    pub fn succeeded(&self) -> bool {
        self.consecutive >= self.rule.hold_steps
    }

    /// Consecutive steps, ending with the last step fed, that satisfied the rule.
    pub fn consecutive(&self) -> u32 {
        self.consecutive
    }
}

/// Timing and geometry of the scripted pick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PickScript {
    /// Height of the pre-grasp pose above the object centre (m).
    pub approach_height: f64,
    /// How far to lift (m).
    pub lift_height: f64,
    /// Duration of the joint-space move above the object (s).
    pub approach_time: f64,
    /// Duration of the straight descent to the grasp pose (s).
    pub descend_time: f64,
    /// Time given to the fingers to close (s).
    pub close_time: f64,
    /// Duration of the straight lift (s).
    pub lift_time: f64,
    /// Time the object is held still at the top, its drift measured (s).
    pub hold_time: f64,
}

impl Default for PickScript {
    fn default() -> Self {
        Self {
            approach_height: 0.12,
            lift_height: 0.12,
            approach_time: 1.2,
            descend_time: 1.0,
            close_time: 0.5,
            lift_time: 1.0,
            hold_time: 1.0,
        }
    }
}

/// The stages of the scripted pick, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PickPhase {
    /// Moving above the object in joint space.
    Approach,
    /// Descending in a straight line to the grasp pose.
    Descend,
    /// Closing the fingers.
    Close,
    /// Lifting in a straight line.
    Lift,
    /// Holding still.
    Hold,
}

impl fmt::Display for PickPhase {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            PickPhase::Approach => "approach",
            PickPhase::Descend => "descent",
            PickPhase::Close => "close",
            PickPhase::Lift => "lift",
            PickPhase::Hold => "hold",
        })
    }
}

/// Why a scripted pick failed.
#[derive(Clone, Debug, PartialEq)]
pub enum PickFailure {
    /// Inverse kinematics found no joint vector for a pose the script needed in `phase`.
    Unreachable {
        /// The phase that needed the pose.
        phase: PickPhase,
    },
    /// When the fingers had closed, they did not hold the object between both pads.
    FingersMissed,
    /// The object was gripped after closing but was no longer held up at the end. `lift` is the
    /// highest its centre rose above rest during the lift and hold (m).
    ObjectSlipped {
        /// Highest lift of the object's centre above rest (m).
        lift: f64,
    },
    /// At the end the object was gripped and lifted, but its centre was `offset` (m) from the TCP,
    /// more than the rule's `max_offset` (m).
    HeldOffCentre {
        /// Distance between the object's centre and the TCP at the end (m).
        offset: f64,
        /// The rule's limit on that distance (m).
        max_offset: f64,
    },
    /// At the end the object was gripped, lifted and centred, but the rule never held for
    /// `hold_steps` consecutive steps; the longest run was `longest_run` steps.
    TimedOut {
        /// Longest run of consecutive steps satisfying the rule.
        longest_run: u32,
        /// Consecutive steps the rule needs.
        hold_steps: u32,
    },
    /// The simulation failed (e.g. its state became non-finite).
    Simulation {
        /// The simulation error, as text.
        message: String,
    },
}

impl PickFailure {
    /// The reason without its measurements, for counting.
    pub fn kind(&self) -> FailureKind {
        match self {
            PickFailure::Unreachable { .. } => FailureKind::Unreachable,
            PickFailure::FingersMissed => FailureKind::FingersMissed,
            PickFailure::ObjectSlipped { .. } => FailureKind::ObjectSlipped,
            PickFailure::HeldOffCentre { .. } => FailureKind::HeldOffCentre,
            PickFailure::TimedOut { .. } => FailureKind::TimedOut,
            PickFailure::Simulation { .. } => FailureKind::Simulation,
        }
    }
}

impl fmt::Display for PickFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PickFailure::Unreachable { phase } => {
                match phase {
                    PickPhase::Approach => f.write_str("pre-grasp pose")?,
                    PickPhase::Descend => f.write_str("descent to the grasp pose")?,
                    other => write!(f, "{other} pose")?,
                }
                f.write_str(" unreachable (IK found no solution)")
            }
            PickFailure::FingersMissed => {
                f.write_str("the fingers closed without gripping the object between both pads")
            }
            PickFailure::ObjectSlipped { lift } => write!(
                f,
                "the object slipped out of the fingers (lifted at most {:.1} cm)",
                lift * 100.0
            ),
            PickFailure::HeldOffCentre { offset, max_offset } => write!(
                f,
                "the object was held {:.1} cm from the TCP, more than the {:.1} cm allowed",
                offset * 100.0,
                max_offset * 100.0
            ),
            PickFailure::TimedOut {
                longest_run,
                hold_steps,
            } => write!(
                f,
                "timed out before the hold ended (the success rule held for at most \
                 {longest_run} of the {hold_steps} consecutive steps it needs)"
            ),
            PickFailure::Simulation { message } => write!(f, "the simulation failed: {message}"),
        }
    }
}

/// The kinds of [`PickFailure`], for counting failures by reason.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum FailureKind {
    /// A pose the script needed was out of reach ([`PickFailure::Unreachable`]).
    Unreachable,
    /// The fingers closed without gripping ([`PickFailure::FingersMissed`]).
    FingersMissed,
    /// The object slipped out ([`PickFailure::ObjectSlipped`]).
    ObjectSlipped,
    /// The object was held too far from the TCP ([`PickFailure::HeldOffCentre`]).
    HeldOffCentre,
    /// The rule never held long enough ([`PickFailure::TimedOut`]).
    TimedOut,
    /// The simulation failed ([`PickFailure::Simulation`]).
    Simulation,
}

impl fmt::Display for FailureKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            FailureKind::Unreachable => "pose unreachable (IK found no solution)",
            FailureKind::FingersMissed => "fingers closed without gripping the object",
            FailureKind::ObjectSlipped => "object slipped out of the fingers",
            FailureKind::HeldOffCentre => "object held too far from the TCP",
            FailureKind::TimedOut => "timed out before the hold ended",
            FailureKind::Simulation => "simulation failed",
        })
    }
}

/// What happened in one scripted pick.
#[derive(Clone, Debug, PartialEq)]
pub struct PickOutcome {
    /// The success rule held for its consecutive steps at some point.
    pub success: bool,
    /// Why the pick failed; `None` exactly when it succeeded.
    pub failure: Option<PickFailure>,
    /// Largest displacement of the object relative to the TCP during the hold (m).
    pub hold_drift: f64,
    /// Object lift above rest at the end (m).
    pub final_lift: f64,
    /// Control steps run.
    pub steps: u32,
}

/// Minimum-jerk blend 0 → 1.
fn smooth(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
}

/// Runs the scripted pick on a freshly reset scene: approach, descend, close, lift, hold.
///
/// A pose the arm cannot reach ends the pick early as [`PickFailure::Unreachable`]; other
/// simulation errors are returned.
pub fn run_scripted_pick(
    scene: &mut Scene,
    object: usize,
    script: &PickScript,
    rule: SuccessRule,
) -> Result<PickOutcome> {
    let phase = Cell::new(PickPhase::Approach);
    let mut tracker = SuccessTracker::new(rule);
    let mut success = false;
    let mut longest_run = 0u32;
    let mut steps = 0u32;
    let mut gripped_after_close = false;
    let mut highest_lift = 0.0f64;
    let mut step = |scene: &mut Scene| -> Result<()> {
        scene.step_control()?;
        steps += 1;
        let status = GraspStatus::of(scene, object);
        success |= tracker.update(&status);
        longest_run = longest_run.max(tracker.consecutive());
        match phase.get() {
            // Its value at the last closing step is what counts.
            PickPhase::Close => gripped_after_close = status.closed_on_object,
            PickPhase::Lift | PickPhase::Hold => highest_lift = highest_lift.max(status.lift),
            PickPhase::Approach | PickPhase::Descend => {}
        }
        Ok(())
    };
    match scripted_grasp_and_lift(scene, object, script, &phase, &mut step) {
        Ok(()) => {}
        Err(SimError::Ik(_)) => {
            // The rule may already have held during a lift cut short.
            return Ok(PickOutcome {
                success,
                failure: (!success).then_some(PickFailure::Unreachable { phase: phase.get() }),
                hold_drift: 0.0,
                final_lift: scene.object_state(object).pose.translation.z
                    - scene.object_rest_height(object),
                steps,
            });
        }
        Err(e) => return Err(e),
    }

    // Hold, measuring the object's drift relative to the TCP.
    phase.set(PickPhase::Hold);
    let relative = |scene: &Scene| {
        let tcp = scene.tcp_pose();
        let p = scene.object_state(object).pose.translation.vector;
        tcp.inverse_transform_point(&Point3::from(p)).coords
    };
    let at_hold = relative(scene);
    let mut hold_drift: f64 = 0.0;
    let period = scene.control_period() as f64;
    for _ in 0..(script.hold_time / period).ceil() as u32 {
        step(scene)?;
        hold_drift = hold_drift.max((relative(scene) - at_hold).norm());
    }
    let end = GraspStatus::of(scene, object);
    let failure = if success {
        None
    } else if !gripped_after_close {
        Some(PickFailure::FingersMissed)
    } else if !end.closed_on_object || end.lift <= rule.min_lift {
        Some(PickFailure::ObjectSlipped { lift: highest_lift })
    } else if end.offset >= rule.max_offset {
        Some(PickFailure::HeldOffCentre {
            offset: end.offset,
            max_offset: rule.max_offset,
        })
    } else {
        Some(PickFailure::TimedOut {
            longest_run,
            hold_steps: rule.hold_steps,
        })
    };
    Ok(PickOutcome {
        success,
        failure,
        hold_drift,
        final_lift: end.lift,
        steps,
    })
}

/// The script up to the end of the lift, picking object `object`; `step` advances one control
/// period.
pub fn grasp_and_lift(
    scene: &mut Scene,
    object: usize,
    script: &PickScript,
    step: &mut dyn FnMut(&mut Scene) -> Result<()>,
) -> Result<()> {
    scripted_grasp_and_lift(scene, object, script, &Cell::new(PickPhase::Approach), step)
}

/// [`grasp_and_lift`], announcing each phase in `phase` as it starts.
fn scripted_grasp_and_lift(
    scene: &mut Scene,
    object: usize,
    script: &PickScript,
    phase: &Cell<PickPhase>,
    step: &mut dyn FnMut(&mut Scene) -> Result<()>,
) -> Result<()> {
    let period = scene.control_period() as f64;
    let centre = scene.object_state(object).pose.translation.vector;
    let yaw = scene.object_grasp_yaw(object);
    let pre = scene.top_down_pose(centre + Vector3::new(0.0, 0.0, script.approach_height), yaw);
    let grasp = scene.top_down_pose(centre, yaw);

    // 1. Open and move above the object in joint space.
    phase.set(PickPhase::Approach);
    scene.set_gripper_open(true)?;
    let start = scene.arm_positions();
    let q_pre = scene.solve_ik(&pre, &start)?;
    let n = (script.approach_time / period).ceil() as u32;
    for i in 1..=n {
        let s = smooth(i as f64 / n as f64) as f32;
        let q: Vec<f32> = start
            .iter()
            .zip(&q_pre)
            .map(|(a, b)| a + (b - a) * s)
            .collect();
        scene.set_arm_targets(&q)?;
        step(scene)?;
    }

    // 2. Descend in a straight line.
    phase.set(PickPhase::Descend);
    let mut seed = q_pre;
    cartesian_move(scene, &pre, &grasp, script.descend_time, &mut seed, step)?;

    // 3. Close.
    phase.set(PickPhase::Close);
    scene.set_gripper_open(false)?;
    for _ in 0..(script.close_time / period).ceil() as u32 {
        step(scene)?;
    }

    // 4. Lift.
    phase.set(PickPhase::Lift);
    let lifted = Isometry3::from_parts(
        (grasp.translation.vector + Vector3::new(0.0, 0.0, script.lift_height)).into(),
        grasp.rotation,
    );
    cartesian_move(scene, &grasp, &lifted, script.lift_time, &mut seed, step)
}

/// Moves the TCP along a straight line from `from` to `to`, solving IK at every control step.
fn cartesian_move(
    scene: &mut Scene,
    from: &Isometry3<f64>,
    to: &Isometry3<f64>,
    duration: f64,
    seed: &mut Vec<f32>,
    step: &mut dyn FnMut(&mut Scene) -> Result<()>,
) -> Result<()> {
    let n = (duration / scene.control_period() as f64).ceil().max(1.0) as u32;
    for i in 1..=n {
        let s = smooth(i as f64 / n as f64);
        let pose = from.lerp_slerp(to, s);
        let q = scene.solve_ik(&pose, seed)?;
        scene.set_arm_targets(&q)?;
        *seed = q;
        step(scene)?;
    }
    Ok(())
}

/// Summary of many scripted picks.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PickReport {
    /// Episodes run.
    pub episodes: u32,
    /// Episodes that succeeded.
    pub successes: u32,
    /// Largest hold drift over successful episodes (m); see [`PickOutcome::hold_drift`].
    pub max_drift: f64,
    /// Mean hold drift over successful episodes (m); 0 when none succeeded.
    pub mean_drift: f64,
    /// Episodes that failed, with their seeds and why.
    pub failures: Vec<(u64, PickFailure)>,
}

impl PickReport {
    /// How many episodes failed for each reason, most frequent first (ties in [`FailureKind`]
    /// order); reasons that did not occur are left out.
    pub fn failure_counts(&self) -> Vec<(FailureKind, u32)> {
        let mut counts = BTreeMap::new();
        for (_, failure) in &self.failures {
            *counts.entry(failure.kind()).or_insert(0u32) += 1;
        }
        let mut counts: Vec<(FailureKind, u32)> = counts.into_iter().collect();
        counts.sort_by_key(|&(_, count)| std::cmp::Reverse(count));
        counts
    }
}

/// Runs `episodes` scripted picks with seeds `seed, seed+1, …`. An episode whose simulation fails
/// counts as [`PickFailure::Simulation`]; only a failed reset stops the evaluation.
pub fn evaluate_scripted_pick(
    scene: &mut Scene,
    episodes: u32,
    seed: u64,
    script: &PickScript,
    rule: SuccessRule,
    mut on_episode: impl FnMut(u64, &PickOutcome),
) -> Result<PickReport> {
    let mut report = PickReport {
        episodes,
        ..PickReport::default()
    };
    let mut drift_sum = 0.0;
    for e in 0..episodes as u64 {
        let episode_seed = seed.wrapping_add(e);
        scene.reset(episode_seed)?;
        let outcome = match run_scripted_pick(scene, 0, script, rule) {
            Ok(outcome) => outcome,
            Err(e) => {
                let failure = PickFailure::Simulation {
                    message: e.to_string(),
                };
                report.failures.push((episode_seed, failure));
                continue;
            }
        };
        on_episode(episode_seed, &outcome);
        match outcome.failure {
            None => {
                report.successes += 1;
                drift_sum += outcome.hold_drift;
                report.max_drift = report.max_drift.max(outcome.hold_drift);
            }
            Some(failure) => report.failures.push((episode_seed, failure)),
        }
    }
    if report.successes > 0 {
        report.mean_drift = drift_sum / report.successes as f64;
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failures_are_counted_by_kind_most_frequent_first() {
        let failures = [
            PickFailure::FingersMissed,
            PickFailure::ObjectSlipped { lift: 0.01 },
            PickFailure::Unreachable {
                phase: PickPhase::Descend,
            },
            PickFailure::ObjectSlipped { lift: 0.03 },
            PickFailure::Unreachable {
                phase: PickPhase::Approach,
            },
            PickFailure::ObjectSlipped { lift: 0.0 },
        ];
        let report = PickReport {
            episodes: 6,
            failures: failures
                .into_iter()
                .enumerate()
                .map(|(i, f)| (i as u64, f))
                .collect(),
            ..PickReport::default()
        };
        assert_eq!(
            report.failure_counts(),
            [
                (FailureKind::ObjectSlipped, 3),
                (FailureKind::Unreachable, 2),
                (FailureKind::FingersMissed, 1),
            ]
        );
        assert!(PickReport::default().failure_counts().is_empty());
    }

    #[test]
    fn failure_messages_give_the_measurements_in_units_a_person_reads() {
        let cases = [
            (
                PickFailure::Unreachable {
                    phase: PickPhase::Descend,
                },
                "descent to the grasp pose unreachable (IK found no solution)",
            ),
            (
                PickFailure::ObjectSlipped { lift: 0.012 },
                "the object slipped out of the fingers (lifted at most 1.2 cm)",
            ),
            (
                PickFailure::HeldOffCentre {
                    offset: 0.095,
                    max_offset: 0.08,
                },
                "the object was held 9.5 cm from the TCP, more than the 8.0 cm allowed",
            ),
            (
                PickFailure::TimedOut {
                    longest_run: 4,
                    hold_steps: 10,
                },
                "timed out before the hold ended (the success rule held for at most 4 of the 10 \
                 consecutive steps it needs)",
            ),
        ];
        for (failure, text) in cases {
            assert_eq!(failure.to_string(), text);
        }
    }
}
