//! The environment contract, mirroring Gymnasium's `Env`: `reset(seed) -> (obs, info)`,
//! `step(action) -> (obs, reward, terminated, truncated, info)`, Box spaces, render modes.

use crate::error::Result;
use crate::spaces::BoxSpace;
use serde::{Deserialize, Serialize};

/// How an environment renders (Gymnasium's `render_mode`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RenderMode {
    /// A text description of the current state, returned by [`Env::render`].
    Ansi,
}

/// What [`Env::render`] returns.
#[derive(Clone, Debug, PartialEq)]
pub enum Frame {
    Text(String),
}

/// Why an episode ended early, beside success and the time limit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EpisodeEvent {
    /// The object left the table (terminates, with a penalty).
    ObjectOffTable,
    /// The physics produced NaN or infinity; the episode was cut and the last finite
    /// observation returned.
    NonFiniteState,
    /// Cartesian mode: inverse kinematics found no joint vector for the commanded pose; the
    /// previous target was kept (the episode goes on).
    IkFailed,
}

/// The reward of one step, split into its terms (they sum to the reward).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RewardTerms {
    /// Progress towards the object: weight × (previous distance − current distance).
    pub approach: f32,
    /// Bonus while the end effector is near the object.
    pub near: f32,
    /// One-time bonus when the object is first grasped in the episode.
    pub grasp: f32,
    /// One-time bonus for lifting and holding (success).
    pub lift_hold: f32,
    /// Per-step time penalty (negative).
    pub time: f32,
    /// Penalty when the object leaves the table (negative).
    pub off_table: f32,
    /// Sparse reward on success.
    pub success: f32,
    /// Staged reward: reaching stage, `(1 − tanh(4·d)) / 3`.
    pub reach: f32,
    /// Staged reward: lifting stage while grasped, `min(lift / (min_lift + 1 cm), 1) / 3`.
    pub lift: f32,
}

impl RewardTerms {
    pub fn total(&self) -> f32 {
        self.approach
            + self.near
            + self.grasp
            + self.lift_hold
            + self.time
            + self.off_table
            + self.success
            + self.reach
            + self.lift
    }
}

/// What `reset` and `step` report besides the observation (Gymnasium's `info` dict).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Info {
    /// The success rule has held for its consecutive steps (SB3 reads this as `is_success`).
    pub success: bool,
    /// The gripper is closed on the object with both pads touching.
    pub grasped: bool,
    /// Distance between the end effector (TCP) and the object centre (m).
    pub ee_object_distance: f32,
    /// Object lift above its resting height (m).
    pub lift: f32,
    /// Consecutive control steps the success rule has held.
    pub success_streak: u32,
    /// The reward split into its terms.
    pub reward_terms: RewardTerms,
    /// Control steps since reset.
    pub elapsed_steps: u32,
    /// Anything unusual this step.
    pub events: Vec<EpisodeEvent>,
    /// The physical parameters drawn for this episode (domain randomisation).
    pub episode_params: Option<EpisodeParams>,
}

/// The randomised quantities of an episode, reported in the reset info.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EpisodeParams {
    pub object_size: f32,
    pub object_mass: f32,
    pub object_friction: f32,
    pub arm_damping: Vec<f32>,
    pub gain_scale: f32,
    pub latency_steps: u32,
}

/// The result of [`Env::step`].
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    pub obs: Vec<f32>,
    pub reward: f32,
    /// The episode reached a terminal state of the task (success, object off the table).
    pub terminated: bool,
    /// The episode was cut for a reason outside the task (time limit, non-finite physics).
    pub truncated: bool,
    pub info: Info,
}

/// Metadata of an environment, like Gymnasium's `metadata` dict.
#[derive(Clone, Debug, PartialEq)]
pub struct Metadata {
    pub id: &'static str,
    pub render_modes: Vec<RenderMode>,
    /// Control steps per second.
    pub render_fps: f32,
}

/// A reinforcement-learning environment with continuous (Box) observation and action spaces.
pub trait Env: Send {
    fn metadata(&self) -> Metadata;
    fn observation_space(&self) -> &BoxSpace;
    fn action_space(&self) -> &BoxSpace;
    fn render_mode(&self) -> Option<RenderMode>;

    /// Starts an episode. `Some(seed)` re-seeds the environment's random stream (the same seed
    /// gives the same episode); `None` continues the stream.
    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info)>;

    /// Applies one action for one control period. Actions outside the action space are clipped
    /// to it; NaN, infinite or wrong-length actions are errors and change nothing.
    fn step(&mut self, action: &[f32]) -> Result<Step>;

    /// Renders in the environment's render mode; `None` when it has none.
    fn render(&mut self) -> Result<Option<Frame>>;

    /// Releases resources. The environment must not be used afterwards.
    fn close(&mut self) {}
}
