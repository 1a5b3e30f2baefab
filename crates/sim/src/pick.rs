//! A scripted top-down pick, and the grasp task's success rule.
//!
//! The script: open, move above an object with the fingers across its narrowest width, descend,
//! close, lift, hold. It drives the arm only through joint position targets (what a policy will do), so
//! its success shows the scene can be grasped with the controls the environment exposes.

use crate::error::Result;
use crate::scene::Scene;
use rapier3d::na::{Isometry3, Point3, Vector3};

/// The task's success rule: gripper closed on the object, object lifted, object centred in the
/// gripper, all held for a number of consecutive control steps.
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

/// What the success rule sees at one control step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GraspStatus {
    /// The gripper is commanded closed, both pads touch the object and the fingers are stopped
    /// by it (opening above 5 mm).
    pub closed_on_object: bool,
    /// Object centre height above its resting height (m).
    pub lift: f64,
    /// Distance between the object centre and the TCP (m).
    pub offset: f64,
}

impl GraspStatus {
    /// Reads the scene about object `object` (its index).
    pub fn of(scene: &Scene, object: usize) -> Self {
        let contacts = scene.finger_contacts(object);
        let closed_on_object = scene.gripper_target() < scene.max_opening() * 0.5
            && contacts[0]
            && contacts[1]
            && scene.gripper_opening() > 0.005;
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
    pub rule: SuccessRule,
    consecutive: u32,
}

impl SuccessTracker {
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

    pub fn succeeded(&self) -> bool {
        self.consecutive >= self.rule.hold_steps
    }

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
    /// Durations (s).
    pub approach_time: f64,
    pub descend_time: f64,
    pub close_time: f64,
    pub lift_time: f64,
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

/// What happened in one scripted pick.
#[derive(Clone, Debug, PartialEq)]
pub struct PickOutcome {
    /// The success rule held for its consecutive steps at some point.
    pub success: bool,
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

/// Runs the scripted pick of object `object` (its index) on a freshly reset scene: approach,
/// descend, close, lift, hold.
pub fn run_scripted_pick(
    scene: &mut Scene,
    object: usize,
    script: &PickScript,
    rule: SuccessRule,
) -> Result<PickOutcome> {
    let mut tracker = SuccessTracker::new(rule);
    let mut success = false;
    let mut steps = 0u32;
    let mut step = |scene: &mut Scene| -> Result<()> {
        scene.step_control()?;
        steps += 1;
        success |= tracker.update(&GraspStatus::of(scene, object));
        Ok(())
    };
    grasp_and_lift(scene, object, script, &mut step)?;

    // Hold, measuring the object's drift relative to the TCP.
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
    let final_lift =
        scene.object_state(object).pose.translation.z - scene.object_rest_height(object);
    Ok(PickOutcome {
        success,
        hold_drift,
        final_lift,
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
    let period = scene.control_period() as f64;
    let centre = scene.object_state(object).pose.translation.vector;
    let yaw = scene.object_grasp_yaw(object);
    let pre = scene.top_down_pose(centre + Vector3::new(0.0, 0.0, script.approach_height), yaw);
    let grasp = scene.top_down_pose(centre, yaw);

    // 1. Open and move above the object in joint space.
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
    let mut seed = q_pre;
    cartesian_move(scene, &pre, &grasp, script.descend_time, &mut seed, step)?;

    // 3. Close.
    scene.set_gripper_open(false)?;
    for _ in 0..(script.close_time / period).ceil() as u32 {
        step(scene)?;
    }

    // 4. Lift.
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
    pub episodes: u32,
    pub successes: u32,
    /// Largest and mean hold drift over successful episodes (m).
    pub max_drift: f64,
    pub mean_drift: f64,
    /// Episodes that failed, with their seeds and a reason.
    pub failures: Vec<(u64, String)>,
}

/// Runs `episodes` scripted picks of object 0 with seeds `seed, seed+1, …`.
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
        match run_scripted_pick(scene, 0, script, rule) {
            Ok(outcome) => {
                on_episode(episode_seed, &outcome);
                if outcome.success {
                    report.successes += 1;
                    drift_sum += outcome.hold_drift;
                    report.max_drift = report.max_drift.max(outcome.hold_drift);
                } else {
                    report.failures.push((
                        episode_seed,
                        format!("not grasped (final lift {:.3} m)", outcome.final_lift),
                    ));
                }
            }
            Err(e) => report.failures.push((episode_seed, e.to_string())),
        }
    }
    if report.successes > 0 {
        report.mean_drift = drift_sum / report.successes as f64;
    }
    Ok(report)
}
