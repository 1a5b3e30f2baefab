//! `FaArmPickPlace-v0`: pick the object and bring it to a random goal — on the table or up to
//! `goal_max_height` above it, shown in the observation. Success (ManiSkill's PickCube rule):
//! the object's centre is within `goal_tolerance` of the goal and slower than
//! `max_object_speed`, for `success_hold_steps` consecutive control steps.

use crate::arm::observation::rich_observation;
use crate::arm::{
    ArmEnv, ArmEnvConfig, ArmState, Evaluation, NoiseGroup, ObsWriter, RewardSettings, Task,
    TaskFlags, TaskSettings,
};
use crate::config::{check_at_least_one, check_non_negative, check_positive};
use crate::core::{EpisodeEvent, NamedValues, RenderMode};
use crate::error::{EnvError, Result};
use fairgrasp_sim::rapier3d::na::Vector3;
use fairgrasp_sim::scene::Scene;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// The Gymnasium id of the pick-and-place task.
pub const ENV_ID: &str = "FaArmPickPlace-v0";

/// The `[task]` section of the pick-and-place task.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PickPlaceSettings {
    /// Control steps before the episode is truncated.
    pub max_episode_steps: u32,
    /// Goals are drawn up to this height above the object's resting height (m); 0 keeps them
    /// on the table.
    pub goal_max_height: f32,
    /// Largest distance between the object's centre and the goal that counts as placed (m).
    pub goal_tolerance: f32,
    /// The object must be slower than this to count as placed (m/s).
    pub max_object_speed: f32,
    /// Consecutive control steps the success conditions must hold.
    pub success_hold_steps: u32,
    /// How [`crate::Env::render`] renders; `None`: it returns nothing.
    pub render_mode: Option<RenderMode>,
}

impl Default for PickPlaceSettings {
    fn default() -> Self {
        Self {
            max_episode_steps: 100,
            goal_max_height: 0.2,
            goal_tolerance: 0.025,
            max_object_speed: 0.05,
            success_hold_steps: 10,
            render_mode: None,
        }
    }
}

impl TaskSettings for PickPlaceSettings {
    type Task = PickPlace;

    fn max_episode_steps(&self) -> u32 {
        self.max_episode_steps
    }

    fn render_mode(&self) -> Option<RenderMode> {
        self.render_mode
    }

    fn validate(&self) -> Result<()> {
        check_at_least_one("task.max_episode_steps", self.max_episode_steps)?;
        check_non_negative("task.goal_max_height", self.goal_max_height)?;
        if self.goal_max_height > 0.35 {
            return Err(EnvError::config(
                "task.goal_max_height",
                "goals above 35 cm leave the workspace; use at most 0.35",
            ));
        }
        check_positive("task.goal_tolerance", self.goal_tolerance)?;
        check_positive("task.max_object_speed", self.max_object_speed)?;
        check_at_least_one("task.success_hold_steps", self.success_hold_steps)?;
        Ok(())
    }
}

/// Which reward the pick-and-place task pays.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlaceRewardKind {
    /// `success` on success, else 0.
    Sparse,
    /// ManiSkill's PickCube stages, shifted to be ≤ 0 per step: `(reach + grasped + place) / 3
    /// − 1`, with reach = 1 − tanh(4·d(TCP, object)), place = 1 − tanh(4·d(object, goal)) while
    /// grasped or at the goal. Knocking the object off the table costs −1 for every remaining
    /// step.
    Staged,
}

/// The `[reward]` section of the pick-and-place task.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PickPlaceReward {
    /// Which reward to pay.
    pub kind: PlaceRewardKind,
    /// Paid on success.
    pub success: f32,
}

impl Default for PickPlaceReward {
    fn default() -> Self {
        Self {
            kind: PlaceRewardKind::Staged,
            success: 10.0,
        }
    }
}

impl RewardSettings for PickPlaceReward {
    fn validate(&self) -> Result<()> {
        check_non_negative("reward.success", self.success)
    }
}

/// The pick-and-place task's whole configuration.
pub type PickPlaceConfig = ArmEnvConfig<PickPlaceSettings, PickPlaceReward>;
/// The pick-and-place environment.
pub type PickPlaceEnv = ArmEnv<PickPlace>;

/// Counts consecutive control steps that satisfy a condition.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Streak(pub u32);

impl Streak {
    /// Feeds one step; returns the new count.
    pub fn update(&mut self, holds: bool) -> u32 {
        self.0 = if holds { self.0 + 1 } else { 0 };
        self.0
    }
}

/// The pick-and-place task (object 0; any others are obstacles).
pub struct PickPlace {
    settings: PickPlaceSettings,
    reward: PickPlaceReward,
    /// The goal of this episode (arm base frame).
    goal: Vector3<f64>,
    streak: Streak,
}

impl PickPlace {
    /// The goal of the current episode, in the arm base frame (m).
    pub fn goal(&self) -> Vector3<f64> {
        self.goal
    }

    fn object_to_goal(&self, s: &ArmState) -> Vector3<f64> {
        self.goal - s.objects[0].pose.translation.vector
    }
}

/// Pick-and-place's flags for one step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlaceFlags {
    /// The fingers are closed on the object.
    pub grasped: bool,
    /// The object's lift above its rest (m).
    pub lift: f64,
    /// From the object's centre to the goal (m).
    pub object_goal_distance: f64,
    /// The object is within the goal's tolerance.
    pub placed: bool,
    /// Steps in a row the object has rested placed.
    pub success_streak: u32,
}

impl TaskFlags for PlaceFlags {
    fn named(&self) -> NamedValues {
        NamedValues::new()
            .with("grasped", self.grasped as u8 as f32)
            .with("lift", self.lift as f32)
            .with("object_goal_distance", self.object_goal_distance as f32)
            .with("placed", self.placed as u8 as f32)
            .with("success_streak", self.success_streak as f32)
    }
}

impl Task for PickPlace {
    type Settings = PickPlaceSettings;
    type Reward = PickPlaceReward;
    type Flags = PlaceFlags;
    const ID: &'static str = ENV_ID;

    fn new(config: &PickPlaceConfig, scene: &Scene) -> Result<Self> {
        if scene.arm_dof() != 6 {
            return Err(EnvError::config(
                "scene.arm.urdf",
                "the pick-and-place task needs a six-joint arm",
            ));
        }
        Ok(Self {
            settings: config.task.clone(),
            reward: config.reward.clone(),
            goal: Vector3::zeros(),
            streak: Streak::default(),
        })
    }

    fn initialize_episode(&mut self, scene: &mut Scene, rng: &mut ChaCha8Rng) -> Result<()> {
        scene.place_objects_at_random(rng)?;
        let area = &scene.config().placement;
        let [x, y] =
            [0, 1].map(|k| (area.center[k] + (rng.random::<f32>() - 0.5) * area.size[k]) as f64);
        let rest_z = scene.object_rest_height(0) - scene.base_pose().translation.z;
        let height = rng.random::<f64>() * self.settings.goal_max_height as f64;
        self.goal = Vector3::new(x, y, rest_z + height);
        self.streak = Streak::default();
        Ok(())
    }

    fn observe(&self, s: &ArmState, previous_action: &[f32], out: &mut ObsWriter) {
        rich_observation(s, 0, previous_action, out);
        out.push3(NoiseGroup::None, &self.goal);
        out.push3(NoiseGroup::ObjectPosition, &self.object_to_goal(s));
    }

    fn evaluate(&mut self, scene: &Scene, s: &ArmState) -> Evaluation<PlaceFlags> {
        let to_goal = self.object_to_goal(s).norm();
        let speed = s.objects[0].linvel.norm();
        let placed = to_goal < self.settings.goal_tolerance as f64;
        let still = speed < self.settings.max_object_speed as f64;
        let streak = self.streak.update(placed && still);
        Evaluation {
            success: streak >= self.settings.success_hold_steps,
            failure: scene
                .object_off_table(0)
                .then_some(EpisodeEvent::ObjectOffTable),
            flags: PlaceFlags {
                grasped: s.grasped(0),
                lift: s.lift(0),
                object_goal_distance: to_goal,
                placed,
                success_streak: streak,
            },
        }
    }

    fn reward(&mut self, e: &Evaluation<PlaceFlags>, s: &ArmState, steps_left: u32) -> NamedValues {
        let mut terms = NamedValues::new();
        let success = if e.success { self.reward.success } else { 0.0 };
        match self.reward.kind {
            PlaceRewardKind::Sparse => terms.set("success", success),
            PlaceRewardKind::Staged => {
                let third = 1.0 / 3.0;
                let grasped = s.grasped(0);
                let reach = 1.0 - (4.0 * s.tcp_to_object(0).norm() as f32).tanh();
                let to_goal = self.object_to_goal(s).norm() as f32;
                let placed = e.flags.placed;
                // Grasped counts as done once the object is at its goal, so releasing it
                // there (goals on the table) is not punished.
                let hold = grasped || placed;
                terms.set("reach", third * if hold { 1.0 } else { reach });
                terms.set("grasp", if hold { third } else { 0.0 });
                let place = 1.0 - (4.0 * to_goal).tanh();
                terms.set("place", if hold { third * place } else { 0.0 });
                terms.set("time", -1.0);
                let off = e.failure.is_some();
                terms.set("off_table", if off { -(steps_left as f32) } else { 0.0 });
                terms.set("success", success);
            }
        }
        terms
    }

    fn describe(&self, s: &ArmState) -> String {
        let o = s.objects[0].pose.translation.vector;
        format!(
            "object = ({:.3}, {:.3}, {:.3}) m, goal = ({:.3}, {:.3}, {:.3}) m, {:.1} cm away",
            o.x,
            o.y,
            o.z,
            self.goal.x,
            self.goal.y,
            self.goal.z,
            self.object_to_goal(s).norm() * 100.0
        )
    }
}
