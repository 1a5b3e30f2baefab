//! `FaArmGrasp-v0`: pick up the object and hold it lifted.
//!
//! Success: the gripper is closed on the object, the object is at least `success_min_lift`
//! above its resting height and within `success_max_offset` of the TCP, for
//! `success_hold_steps` consecutive control steps. The object falling off the table ends the
//! episode as a failure.
//!
//! The rule is the simulator's [`SuccessRule`] configured by `[task]`; [`GraspSuccess`] applies
//! it to an episode's states. Training's [`Task::evaluate`] and the deployment loop (through
//! [`Task::success_judge`]) run that same type, and the scripted pick judges by
//! [`GraspSettings::success_rule`].

use crate::arm::observation::{rich_observation, shape_observation};
use crate::arm::{
    ArmEnv, ArmEnvConfig, ArmState, Evaluation, NoiseGroup, ObsWriter, RewardSettings,
    SuccessJudge, Task, TaskFlags, TaskSettings,
};
use crate::config::{check_at_least_one, check_non_negative, check_positive};
use crate::core::{EpisodeEvent, NamedValues, RenderMode};
use crate::error::{EnvError, Result};
use fairgrasp_sim::pick::{GraspStatus, SuccessRule, SuccessTracker};
use fairgrasp_sim::rapier3d::na::{Isometry3, Vector3};
use fairgrasp_sim::scene::Scene;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::{PI, TAU};

/// The Gymnasium id of the grasp task.
pub const ENV_ID: &str = "FaArmGrasp-v0";

/// Which observation vector the grasp task returns.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObservationPreset {
    /// The design's 23 values: joint angles (6), EE position (3), EE Euler angles (3), object
    /// position (3), object quaternion (4), EE linear velocity (3), gripper opening (1).
    Seed23,
    /// 33 values plus the previous action, chosen for learning: continuous orientations,
    /// velocities, the EE→object vector, contact flags (docs/tasks.md). With random shapes,
    /// 5 more: the object's half extents and its twofold relative yaw.
    Rich,
}

/// The `[task]` section of the grasp task.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GraspSettings {
    /// Which observation vector to return.
    pub observation: ObservationPreset,
    /// Control steps before the episode is truncated.
    pub max_episode_steps: u32,
    /// Lift above the resting height that counts as lifted (m).
    pub success_min_lift: f32,
    /// Largest object–TCP distance that counts as centred (m).
    pub success_max_offset: f32,
    /// Consecutive control steps the success conditions must hold.
    pub success_hold_steps: u32,
    /// How [`crate::Env::render`] renders; `None`: it returns nothing.
    pub render_mode: Option<RenderMode>,
}

impl Default for GraspSettings {
    fn default() -> Self {
        // The rule's figures have one home: the simulator's rule, which the scripted pick
        // defaults to.
        let rule = SuccessRule::default();
        Self {
            observation: ObservationPreset::Rich,
            max_episode_steps: 100,
            success_min_lift: rule.min_lift as f32,
            success_max_offset: rule.max_offset as f32,
            success_hold_steps: rule.hold_steps,
            render_mode: None,
        }
    }
}

impl GraspSettings {
    /// The success rule these settings configure: what training, the twin, the deployment loop
    /// and the scripted pick judge a grasp by.
    pub fn success_rule(&self) -> SuccessRule {
        SuccessRule {
            min_lift: self.success_min_lift as f64,
            max_offset: self.success_max_offset as f64,
            hold_steps: self.success_hold_steps,
        }
    }
}

/// What the grasp rule reads of a state: object 0 held, its lift and its distance from the TCP.
pub fn grasp_status(state: &ArmState) -> GraspStatus {
    GraspStatus {
        closed_on_object: state.grasped(0),
        lift: state.lift(0),
        offset: state.tcp_to_object(0).norm(),
    }
}

/// The grasp task's success rule over one episode's states: [`GraspStatus::satisfies`] counted
/// over consecutive control steps until `success_hold_steps`.
#[derive(Clone, Debug)]
pub struct GraspSuccess(SuccessTracker);

impl GraspSuccess {
    /// A judge for a new episode.
    pub fn new(settings: &GraspSettings) -> Self {
        Self(SuccessTracker::new(settings.success_rule()))
    }

    /// Feeds one control step's reading; true once the rule has held for its hold steps.
    pub fn update_status(&mut self, status: &GraspStatus) -> bool {
        self.0.update(status)
    }

    /// Consecutive control steps the conditions have held.
    pub fn streak(&self) -> u32 {
        self.0.consecutive()
    }
}

impl SuccessJudge for GraspSuccess {
    fn update(&mut self, state: &ArmState) -> bool {
        self.update_status(&grasp_status(state))
    }
}

impl TaskSettings for GraspSettings {
    type Task = Grasp;

    fn max_episode_steps(&self) -> u32 {
        self.max_episode_steps
    }

    fn render_mode(&self) -> Option<RenderMode> {
        self.render_mode
    }

    fn validate(&self) -> Result<()> {
        check_at_least_one("task.max_episode_steps", self.max_episode_steps)?;
        check_positive("task.success_min_lift", self.success_min_lift)?;
        check_positive("task.success_max_offset", self.success_max_offset)?;
        check_at_least_one("task.success_hold_steps", self.success_hold_steps)?;
        Ok(())
    }
}

/// Which reward the grasp task pays.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RewardKind {
    /// `success` on success, else 0.
    Sparse,
    /// The design's mix: approach progress, near bonus, one-time grasp and lift-hold bonuses,
    /// time penalty.
    Hybrid,
    /// Dense and staged like ManiSkill's PickCube, shifted to be ≤ 0 so that finishing early
    /// always pays: `(reach + grasped + lift) / 3 − 1` per step, with reach = 1 − tanh(4·d),
    /// grasped ∈ {0, 1}, lift = min(lift / (min_lift + 1 cm), 1) while grasped.
    /// Knocking the object off the table costs the worst reward for every remaining step, so
    /// it never pays to end an episode that way.
    Staged,
}

/// The `[reward]` section of the grasp task. Every term is reported in `info.reward_terms`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GraspReward {
    /// Which reward to pay.
    pub kind: RewardKind,
    /// × (previous EE–object distance − current), per step.
    pub approach: f32,
    /// Paid every step the EE is within `near_radius` of the object.
    pub near: f32,
    /// EE–object distance within which `near` is paid (m), positive.
    pub near_radius: f32,
    /// Paid once per episode, the first time the object is grasped.
    pub grasp: f32,
    /// Paid once per episode, on success (lifted and held).
    pub lift_hold: f32,
    /// Subtracted every step.
    pub time_penalty: f32,
    /// Subtracted when the object leaves the table (the episode terminates).
    pub off_table_penalty: f32,
    /// Paid on success (sparse and staged kinds).
    pub success: f32,
    /// Subtracted each step the gripper command differs from the previous step's (staged and
    /// hybrid kinds). 0 (the default): gripper commands are free, and a policy may toggle the
    /// gripper on its way to the object, where nothing in the reward tells the two apart.
    pub gripper_switch: f32,
    /// Staged kind: up to this much subtracted per step for the gripper's yaw misalignment
    /// with the object, `align · |ψ| / 45° · (1 − tanh(4·d))` with ψ the relative yaw folded
    /// into ±45° (a box's fourfold symmetry) and d the TCP–object distance: nothing far away,
    /// the full weight at the object. 0 (the default): any yaw is free, and a policy may close
    /// across a box's corners, which rapier forgives and MuJoCo's cell does not
    /// (docs/deployment.md).
    pub align: f32,
    /// Staged kind: up to this much subtracted per step while the object slides on the table
    /// before it is grasped, `push · min(1, |v_xy| / 5 cm/s)` with v_xy the object's horizontal
    /// velocity. 0 (the default): shoving the object is free, and a policy may close while the
    /// arm still moves sideways, which rapier's contacts forgive and MuJoCo's do not
    /// (docs/deployment.md).
    pub push: f32,
    /// Staged kind: subtracted when the gripper is commanded closed with the object between the
    /// pads but off their centre, `center · min(1, |y| / 1 cm)` with y the object's offset along
    /// the fingers' axis (the TCP's y) at the previous step, when the command was decided;
    /// "between": within 2 cm of the TCP along x and z, inside the open stroke along y. 0 (the
    /// default): an off-centre close is free, and the first finger to arrive shoves the object
    /// towards the other, which rapier forgives and MuJoCo's cell does not (docs/deployment.md).
    pub center: f32,
    /// Staged and hybrid kinds: subtracted each step the gripper turns about the vertical,
    /// `turn · min(1, |Δψ| / 0.1 rad)` with Δψ the TCP's heading change over the step (0.1 rad:
    /// the Cartesian mode's largest yaw step by default). 0 (the default): turning is free,
    /// and a policy may spin the wrist at full speed on its way down whatever the object's yaw,
    /// sweeping the open fingers over the object's top, which a controller's collision
    /// detection stops at low speed scales (docs/deployment.md).
    pub turn: f32,
}

/// The heading change that costs `reward.turn` in full (rad).
const FULL_TURN_RAD: f64 = 0.1;

impl Default for GraspReward {
    fn default() -> Self {
        Self {
            kind: RewardKind::Hybrid,
            approach: 0.1,
            near: 0.5,
            near_radius: 0.10,
            grasp: 5.0,
            lift_hold: 10.0,
            time_penalty: 0.01,
            off_table_penalty: 10.0,
            success: 10.0,
            gripper_switch: 0.0,
            align: 0.0,
            push: 0.0,
            center: 0.0,
            turn: 0.0,
        }
    }
}

impl RewardSettings for GraspReward {
    fn validate(&self) -> Result<()> {
        for (key, v) in [
            ("reward.approach", self.approach),
            ("reward.near", self.near),
            ("reward.grasp", self.grasp),
            ("reward.lift_hold", self.lift_hold),
            ("reward.time_penalty", self.time_penalty),
            ("reward.off_table_penalty", self.off_table_penalty),
            ("reward.success", self.success),
            ("reward.gripper_switch", self.gripper_switch),
            ("reward.align", self.align),
            ("reward.push", self.push),
            ("reward.center", self.center),
            ("reward.turn", self.turn),
        ] {
            check_non_negative(key, v)?;
        }
        check_positive("reward.near_radius", self.near_radius)
    }
}

/// Everything that defines a grasp environment.
pub type GraspConfig = ArmEnvConfig<GraspSettings, GraspReward>;
/// The grasp environment.
pub type GraspEnv = ArmEnv<Grasp>;

/// The grasp task (object 0 is the one to lift; any others are obstacles).
pub struct Grasp {
    settings: GraspSettings,
    reward: GraspReward,
    random_shapes: bool,
    success: GraspSuccess,
    previous_distance: f32,
    grasp_paid: bool,
    /// The gripper command of the previous step (for `reward.gripper_switch` and
    /// `reward.center`).
    previous_closing: bool,
    /// The object's offset between the pads at the previous step (for `reward.center`).
    previous_off_centre: Option<f64>,
    /// The TCP's heading at the previous step (for `reward.turn`).
    previous_heading: f64,
}

/// The TCP's heading about the vertical (rad): the direction of its x axis on the table,
/// defined for any downward-pointing TCP (Euler angles flip near a top-down pose).
fn heading(tcp: &Isometry3<f64>) -> f64 {
    let x = tcp.rotation * Vector3::x();
    x.y.atan2(x.x)
}

/// Object `i`'s offset along the fingers' axis (the TCP's y, m) while it sits between the
/// pads: within 2 cm of the TCP along its x and z, inside the open stroke along y.
pub(crate) fn off_centre(state: &ArmState, i: usize) -> Option<f64> {
    let local = state.tcp.rotation.inverse() * state.tcp_to_object(i);
    let between = local.x.abs() < 0.02
        && local.z.abs() < 0.02
        && local.y.abs() < 0.5 * state.gripper_max_opening as f64;
    between.then_some(local.y)
}

/// The grasp's flags for one step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GraspFlags {
    /// The fingers are closed on the object.
    pub grasped: bool,
    /// The object's lift above its rest (m).
    pub lift: f64,
    /// From the TCP to the object's centre (m).
    pub ee_object_distance: f64,
    /// Steps in a row the success rule has held.
    pub success_streak: u32,
}

impl TaskFlags for GraspFlags {
    fn named(&self) -> NamedValues {
        NamedValues::new()
            .with("grasped", self.grasped as u8 as f32)
            .with("lift", self.lift as f32)
            .with("ee_object_distance", self.ee_object_distance as f32)
            .with("success_streak", self.success_streak as f32)
    }
}

impl Task for Grasp {
    type Settings = GraspSettings;
    type Reward = GraspReward;
    type Flags = GraspFlags;
    const ID: &'static str = ENV_ID;

    fn new(config: &GraspConfig, scene: &Scene) -> Result<Self> {
        if scene.arm_dof() != 6 {
            return Err(EnvError::config(
                "scene.arm.urdf",
                format!(
                    "the grasp task needs a six-joint arm, this one has {}",
                    scene.arm_dof()
                ),
            ));
        }
        Ok(Self {
            settings: config.task.clone(),
            reward: config.reward.clone(),
            random_shapes: config.shapes.enabled,
            success: GraspSuccess::new(&config.task),
            previous_distance: 0.0,
            grasp_paid: false,
            previous_closing: false,
            previous_off_centre: None,
            previous_heading: 0.0,
        })
    }

    fn initialize_episode(&mut self, scene: &mut Scene, rng: &mut ChaCha8Rng) -> Result<()> {
        scene.place_objects_at_random(rng)?;
        self.success = GraspSuccess::new(&self.settings);
        self.grasp_paid = false;
        self.previous_closing = scene.gripper_commanded_closed();
        self.previous_off_centre = if self.reward.center > 0.0 {
            off_centre(&ArmState::from_scene(scene), 0)
        } else {
            None
        };
        self.previous_heading = heading(&scene.tcp_pose());
        let tcp = scene.tcp_pose().translation.vector;
        self.previous_distance =
            (scene.object_state(0).pose.translation.vector - tcp).norm() as f32;
        Ok(())
    }

    fn observe(&self, s: &ArmState, previous_action: &[f32], out: &mut ObsWriter) {
        use NoiseGroup::*;
        let object = &s.objects[0];
        match self.settings.observation {
            ObservationPreset::Seed23 => {
                out.push(JointPosition, &s.q);
                out.push3(EePosition, &s.tcp.translation.vector);
                let (r, p, y) = s.tcp.rotation.euler_angles();
                out.push(EeOrientation, &[r as f32, p as f32, y as f32]);
                out.push3(ObjectPosition, &object.pose.translation.vector);
                let q = object.pose.rotation.quaternion();
                out.push(
                    ObjectOrientation,
                    &[q.i as f32, q.j as f32, q.k as f32, q.w as f32],
                );
                out.push3(EeVelocity, &s.tcp_linvel);
                out.push1(Gripper, s.gripper_opening);
            }
            ObservationPreset::Rich => {
                rich_observation(s, 0, previous_action, out);
                if self.random_shapes {
                    shape_observation(s, 0, out);
                }
            }
        }
    }

    fn evaluate(&mut self, scene: &Scene, state: &ArmState) -> Evaluation<GraspFlags> {
        let status = grasp_status(state);
        let success = self.success.update_status(&status);
        Evaluation {
            success,
            failure: scene
                .object_off_table(0)
                .then_some(EpisodeEvent::ObjectOffTable),
            flags: GraspFlags {
                grasped: status.closed_on_object,
                lift: status.lift,
                ee_object_distance: status.offset,
                success_streak: self.success.streak(),
            },
        }
    }

    fn success_judge(&self) -> Option<Box<dyn SuccessJudge>> {
        Some(Box::new(GraspSuccess::new(&self.settings)))
    }

    fn reward(
        &mut self,
        e: &Evaluation<GraspFlags>,
        state: &ArmState,
        steps_left: u32,
    ) -> NamedValues {
        let r = &self.reward;
        let distance = state.tcp_to_object(0).norm() as f32;
        let grasped = state.grasped(0);
        let off_table = e.failure.is_some();
        let mut terms = NamedValues::new();
        match r.kind {
            RewardKind::Sparse => {
                terms.set("success", if e.success { r.success } else { 0.0 });
            }
            RewardKind::Staged => {
                let third = 1.0 / 3.0;
                terms.set("reach", third * (1.0 - (4.0 * distance).tanh()));
                terms.set("grasp", if grasped { third } else { 0.0 });
                // Linear in the lift: a steady gradient from the table up (a tanh saturating
                // at the goal gave too little pull for the first centimetres).
                let goal = self.settings.success_min_lift + 0.01;
                let lift = (state.lift(0) as f32 / goal).clamp(0.0, 1.0);
                terms.set("lift", if grasped { third * lift } else { 0.0 });
                terms.set("time", -1.0);
                terms.set(
                    "off_table",
                    if off_table { -(steps_left as f32) } else { 0.0 },
                );
                terms.set("success", if e.success { r.success } else { 0.0 });
                if r.align > 0.0 {
                    let quarter = std::f64::consts::FRAC_PI_4;
                    let yaw = (state.relative_yaw(0) + quarter).rem_euclid(2.0 * quarter) - quarter;
                    let near = 1.0 - (4.0 * distance).tanh();
                    terms.set("align", -r.align * (yaw.abs() / quarter) as f32 * near);
                }
                if r.push > 0.0 {
                    let v = state.objects[0].linvel.xy().norm() as f32;
                    let sliding = if grasped { 0.0 } else { (v / 0.05).min(1.0) };
                    terms.set("push", -r.push * sliding);
                }
                if r.center > 0.0 {
                    let closed_now = state.gripper_closing && !self.previous_closing;
                    let off = self.previous_off_centre.filter(|_| closed_now);
                    let cost = off.map_or(0.0, |y| (y.abs() / 0.01).min(1.0) as f32);
                    terms.set("center", -r.center * cost);
                    self.previous_off_centre = off_centre(state, 0);
                }
            }
            RewardKind::Hybrid => {
                terms.set("approach", r.approach * (self.previous_distance - distance));
                terms.set(
                    "near",
                    if distance < r.near_radius {
                        r.near
                    } else {
                        0.0
                    },
                );
                // One-time bonuses: paid at most once per episode, so dropping and regrasping
                // the object earns nothing more.
                let first_grasp = grasped && !self.grasp_paid;
                self.grasp_paid |= grasped;
                terms.set("grasp", if first_grasp { r.grasp } else { 0.0 });
                terms.set("lift_hold", if e.success { r.lift_hold } else { 0.0 });
                terms.set("time", -r.time_penalty);
                terms.set(
                    "off_table",
                    if off_table { -r.off_table_penalty } else { 0.0 },
                );
            }
        }
        if r.gripper_switch > 0.0 && r.kind != RewardKind::Sparse {
            let switched = state.gripper_closing != self.previous_closing;
            terms.set(
                "gripper_switch",
                if switched { -r.gripper_switch } else { 0.0 },
            );
        }
        if r.turn > 0.0 && r.kind != RewardKind::Sparse {
            let now = heading(&state.tcp);
            let turned = (now - self.previous_heading + PI).rem_euclid(TAU) - PI;
            let cost = (turned.abs() / FULL_TURN_RAD).min(1.0) as f32;
            terms.set("turn", -r.turn * cost);
            self.previous_heading = now;
        }
        self.previous_closing = state.gripper_closing;
        self.previous_distance = distance;
        terms
    }

    fn describe(&self, s: &ArmState) -> String {
        let o = s.objects[0].pose.translation.vector;
        format!(
            "object = ({:.3}, {:.3}, {:.3}) m, lift = {:.1} mm, pads touching = {:?}",
            o.x,
            o.y,
            o.z,
            s.lift(0) * 1000.0,
            s.objects[0].pad_contacts
        )
    }
}

/// Every observation × action × reward variant of the grasp task (for checkers and docs).
pub fn all_variants() -> Vec<(ObservationPreset, crate::arm::ActionMode, RewardKind)> {
    use crate::arm::ActionMode;
    let mut out = Vec::new();
    for obs in [ObservationPreset::Seed23, ObservationPreset::Rich] {
        for mode in [ActionMode::Joint, ActionMode::Cartesian] {
            for reward in [RewardKind::Sparse, RewardKind::Hybrid, RewardKind::Staged] {
                out.push((obs, mode, reward));
            }
        }
    }
    out
}
