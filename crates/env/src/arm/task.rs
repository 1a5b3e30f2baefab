//! What a task is to the shared arm environment: the [`Task`] trait with its settings
//! ([`TaskSettings`], [`RewardSettings`]), flags ([`TaskFlags`], [`Evaluation`]) and success
//! rule ([`SuccessJudge`]), and [`ArmEnvConfig`], the configuration that joins the task's
//! sections to the shared ones. One file, because each names the others.

use crate::arm::camera::CameraObsConfig;
use crate::arm::config::RandomizationConfig;
use crate::arm::control::ControlConfig;
use crate::arm::observation::ObsWriter;
use crate::arm::readings::ReadingsConfig;
use crate::arm::shapes::ShapesConfig;
use crate::arm::state::ArmState;
use crate::core::{EpisodeEvent, NamedValues, RenderMode};
use crate::error::{EnvError, Result};
use fairgrasp_render::{Camera, CameraConfig};
use fairgrasp_sim::scene::{Scene, SceneConfig};
use rand_chacha::ChaCha8Rng;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::fmt::Debug;

/// What a task's evaluation of one step found (ManiSkill's `evaluate()`): its flags typed while
/// the task reads them, named only in [`Info::extras`].
///
/// A task's reward reads its flags as fields, so a flag it never declared does not compile
/// (reading them back by name, a typo read 0 and silently zeroed a reward term). This reads
/// one the grasp declares:
///
/// ```
/// use fairgrasp_env::arm::Evaluation;
/// use fairgrasp_env::tasks::GraspFlags;
/// fn grasped(e: &Evaluation<GraspFlags>) -> bool {
///     e.flags.grasped
/// }
/// ```
///
/// and this one it does not:
///
/// ```compile_fail
/// use fairgrasp_env::arm::Evaluation;
/// use fairgrasp_env::tasks::GraspFlags;
/// fn placed(e: &Evaluation<GraspFlags>) -> bool {
///     e.flags.placed // the grasp declares no `placed`
/// }
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Evaluation<F = NamedValues> {
    /// The success rule holds: the episode terminates.
    pub success: bool,
    /// The task failed for good (e.g. an object fell off the table): the episode terminates.
    pub failure: Option<EpisodeEvent>,
    /// The task's flags and measures.
    pub flags: F,
}

/// A task's flags and measures for one step: a struct of named fields, reported by name.
pub trait TaskFlags: Clone + std::fmt::Debug + Send + 'static {
    /// The flags by name, in a fixed order, as [`Info::extras`] reports them.
    fn named(&self) -> NamedValues;
}

impl<F: TaskFlags> Evaluation<F> {
    /// The evaluation with its flags named, as the env's callers read it.
    pub fn named(&self) -> Evaluation {
        Evaluation {
            success: self.success,
            failure: self.failure,
            flags: self.flags.named(),
        }
    }
}

/// A task on the shared arm environment. One small type per task (see [`crate::tasks`]).
pub trait Task: Send + Sized + 'static {
    /// The `[task]` section.
    type Settings: TaskSettings;
    /// The `[reward]` section.
    type Reward: RewardSettings;
    /// The step's flags and measures ([`Evaluation::flags`]).
    type Flags: TaskFlags;
    /// The registered id (`FaArmGrasp-v0`).
    const ID: &'static str;

    /// Adjusts the scene before it is built (objects, bins).
    fn configure_scene(
        _config: &ArmEnvConfig<Self::Settings, Self::Reward>,
        _scene: &mut SceneConfig,
    ) -> Result<()> {
        Ok(())
    }

    /// The task for a built scene; checks that the scene suits it.
    fn new(config: &ArmEnvConfig<Self::Settings, Self::Reward>, scene: &Scene) -> Result<Self>;

    /// Starts an episode: the arm is at home with this episode's physical parameters and object
    /// shapes; place the objects, draw goals, settle the scene.
    fn initialize_episode(&mut self, scene: &mut Scene, rng: &mut ChaCha8Rng) -> Result<()>;

    /// Control steps before this episode is truncated, given the configured limit (called after
    /// [`Self::initialize_episode`]): sorting shortens it for objects that start sorted.
    fn episode_steps(&self, max_episode_steps: u32) -> u32 {
        max_episode_steps
    }

    /// Writes the observation. `previous_action` is normalised to [-1, 1].
    fn observe(&self, state: &ArmState, previous_action: &[f32], out: &mut ObsWriter);

    /// Evaluates the step just taken.
    fn evaluate(&mut self, scene: &Scene, state: &ArmState) -> Evaluation<Self::Flags>;

    /// Whether the arm goes back to its home pose, gripper open, after the step just evaluated:
    /// a scripted move between the task's stages that the policy does not steer (sorting's
    /// return between picks, as a cell's MoveJ home). The env teleports it there, drops the
    /// actions in flight and evaluates the step again. `false` by default.
    fn return_home(&mut self) -> bool {
        false
    }

    /// The success rule `evaluate` applies, as a judge of states alone for a new episode (the
    /// deployment loop judges its estimated states by it); `None` when success needs the
    /// simulator (sorting's bins).
    fn success_judge(&self) -> Option<Box<dyn SuccessJudge>> {
        None
    }

    /// The reward of the step just taken, by term. `steps_left` counts the control steps left
    /// before the time limit.
    fn reward(
        &mut self,
        evaluation: &Evaluation<Self::Flags>,
        state: &ArmState,
        steps_left: u32,
    ) -> NamedValues;

    /// A line describing the task's state, for the `ansi` render mode.
    fn describe(&self, _state: &ArmState) -> String {
        String::new()
    }
}

/// A task's success rule over the states of one episode, for code that builds its states itself
/// (the deployment loop judges its estimated states): the rule the task's
/// [`Task::evaluate`] applies in training. Fresh for each episode ([`Task::success_judge`]).
pub trait SuccessJudge: Send {
    /// Feeds one control step's state; true while the rule is met (its conditions have held for
    /// the hold steps it needs).
    fn update(&mut self, state: &ArmState) -> bool;
}

/// What the shared arm environment needs from a task's `[task]` section.
pub trait TaskSettings:
    Clone + Debug + Default + PartialEq + Serialize + DeserializeOwned + Send + 'static
{
    /// The task these settings configure: lets code holding a typed configuration build its
    /// env without naming the task ([`crate::arm::erased::nominal_env`]).
    type Task: Task<Settings = Self>;

    /// Control steps before the episode is truncated.
    fn max_episode_steps(&self) -> u32;
    /// How [`crate::Env::render`] renders; `None`: it returns nothing.
    fn render_mode(&self) -> Option<RenderMode>;
    /// Checks ranges; errors name the key (`task.…`).
    fn validate(&self) -> Result<()>;
}

/// What the shared arm environment needs from a task's `[reward]` section.
pub trait RewardSettings:
    Clone + Debug + Default + PartialEq + Serialize + DeserializeOwned + Send + 'static
{
    /// Checks ranges; errors name the key (`reward.…`).
    fn validate(&self) -> Result<()>;
}

/// Everything that defines an arm environment: the shared sections and the task's `T` (`[task]`)
/// and `R` (`[reward]`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(
    deny_unknown_fields,
    default,
    bound = "T: TaskSettings, R: RewardSettings"
)]
pub struct ArmEnvConfig<T, R> {
    /// The `[scene]` section: physics, table, objects, bins, arm and gripper.
    pub scene: SceneConfig,
    /// The `[control]` section: action mapping, limits and the controller model.
    pub control: ControlConfig,
    /// The task's `[task]` section.
    pub task: T,
    /// The task's `[reward]` section.
    pub reward: R,
    /// The `[randomization]` section: domain randomisation.
    pub randomization: RandomizationConfig,
    /// The `[shapes]` section: random object shapes.
    pub shapes: ShapesConfig,
    /// The camera of the `rgb_array` and `depth_array` render modes (unused otherwise).
    pub render: CameraConfig,
    /// The policy's observation from synthesized controller readings, as on the arm.
    pub readings: ReadingsConfig,
    /// The `[camera]` section: the observation mode and the cameras of the pixel modes.
    pub camera: CameraObsConfig,
}

impl<T: TaskSettings, R: RewardSettings> ArmEnvConfig<T, R> {
    /// Checks every range; the error names the key.
    pub fn validate(&self) -> Result<()> {
        self.scene.validate().map_err(|e| match e {
            fairgrasp_sim::SimError::Config { key, problem } => {
                EnvError::config(format!("scene.{key}"), problem)
            }
            other => EnvError::Sim(other),
        })?;
        self.control.validate()?;
        self.task.validate()?;
        self.reward.validate()?;
        self.randomization.validate()?;
        self.shapes.validate()?;
        self.readings.validate()?;
        self.camera.validate()?;
        if !self.readings.enabled && self.control.speed_scales.iter().any(|&s| s != 1.0) {
            return Err(EnvError::config(
                "control.speed_scales",
                "scales below 1 need readings.enabled = true (the observation reads speeds in \
                 the policy's time only through the controller's readings)",
            ));
        }
        Camera::new(self.render.clone())?;
        Ok(())
    }

    /// Parses TOML text, applies `overrides` (`dotted.key=value`), then validates.
    pub fn from_toml_str(text: &str, overrides: &[String]) -> Result<Self> {
        let config: Self = crate::config::parse_toml(text, overrides)?;
        config.validate()?;
        Ok(config)
    }

    /// The configuration as TOML text (e.g. to save it beside a run).
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# could not serialise: {e}\n"))
    }
}
