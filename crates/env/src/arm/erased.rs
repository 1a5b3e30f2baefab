//! An arm env with its task type erased: what code outside training (the twin, the deployment
//! loop) gets from the registry ([`crate::registry::ArmOffer`]), so that it never names a task.
//!
//! - [`ArmWorld`]: the task's nominal scene staged as a world (the twin's): each episode starts
//!   as the env's own reset does with randomisation off, and the task judges every control step;
//! - [`ArmTaskEnv`]: a trained model's env as the deployment loop reads it, never stepped: the
//!   observation, the action mapping, the nominal state and the task's success rule;
//! - [`SuccessJudge`]: a task's success rule applied to the states of one episode.

use crate::arm::task::{ArmEnvConfig, Evaluation, SuccessJudge, Task, TaskSettings};
use crate::arm::{ActionMapper, ArmEnv, ArmState, ReadingsConfig};
use crate::config::from_table;
use crate::core::Env;
use crate::error::Result;
use fairgrasp_sim::scene::Scene;

/// An arm task's scene staged outside training, in its nominal world: no domain randomisation
/// (the real world does not change between episodes), the configured object mass and friction,
/// random object shapes when `[shapes]` enables them.
pub trait ArmWorld: Send {
    /// The scene, for reading its state.
    fn scene(&self) -> &Scene;
    /// The scene to drive and step between the task's judgements.
    fn scene_mut(&mut self) -> &mut Scene;
    /// Arm at home, objects placed by the task from `seed`, scene settled: the env's reset.
    fn start_episode(&mut self, seed: u64) -> Result<()>;
    /// The task's judgement of a state of the scene (success, failure, its flags).
    fn evaluate(&mut self, state: &ArmState) -> Evaluation;
}

impl<T: Task> ArmWorld for ArmEnv<T> {
    fn scene(&self) -> &Scene {
        &self.scene
    }

    fn scene_mut(&mut self) -> &mut Scene {
        &mut self.scene
    }

    fn start_episode(&mut self, seed: u64) -> Result<()> {
        self.reset(Some(seed)).map(|_| ())
    }

    fn evaluate(&mut self, state: &ArmState) -> Evaluation {
        self.task.evaluate(&self.scene, state).named()
    }
}

/// A trained model's env as the deployment reads it: built from the model's settings with
/// randomisation off and never stepped.
pub trait ArmTaskEnv: Env {
    /// The env's scene, built from the model's settings with randomisation off.
    fn scene(&self) -> &Scene;
    /// The true state at the last reset.
    fn state(&self) -> Option<&ArmState>;
    /// The action mapping.
    fn mapper(&self) -> &ActionMapper;
    /// How the policy read the arm in training (`[readings]`).
    fn readings(&self) -> &ReadingsConfig;
    /// Control steps before an episode is truncated, as in training.
    fn max_episode_steps(&self) -> u32;
    /// The observation of a state read outside the simulator ([`ArmEnv::observation_of`]).
    fn observation_of(
        &self,
        state: &ArmState,
        previous_action: &[f32],
        speed_scale: f32,
    ) -> Vec<f32>;
    /// The task's success rule for a new episode; `None` when it needs the simulator.
    fn success_judge(&self) -> Option<Box<dyn SuccessJudge>>;
}

impl<T: Task> ArmTaskEnv for ArmEnv<T> {
    fn scene(&self) -> &Scene {
        &self.scene
    }

    fn state(&self) -> Option<&ArmState> {
        ArmEnv::state(self)
    }

    fn mapper(&self) -> &ActionMapper {
        &self.mapper
    }

    fn readings(&self) -> &ReadingsConfig {
        &self.config.readings
    }

    fn max_episode_steps(&self) -> u32 {
        self.config.task.max_episode_steps()
    }

    fn observation_of(
        &self,
        state: &ArmState,
        previous_action: &[f32],
        speed_scale: f32,
    ) -> Vec<f32> {
        ArmEnv::observation_of(self, state, previous_action, speed_scale)
    }

    fn success_judge(&self) -> Option<Box<dyn SuccessJudge>> {
        self.task.success_judge()
    }
}

/// The env of task `T` in its nominal world: randomisation off, so that the home pose and the
/// objects are the configured ones.
fn nominal<T: Task>(mut config: ArmEnvConfig<T::Settings, T::Reward>) -> Result<ArmEnv<T>> {
    config.randomization.enabled = false;
    ArmEnv::new(config)
}

/// The nominal env of a typed configuration (randomisation off), whatever its task.
pub fn nominal_env<S: TaskSettings>(
    config: ArmEnvConfig<S, <S::Task as Task>::Reward>,
) -> Result<Box<dyn ArmTaskEnv>> {
    Ok(Box::new(nominal::<S::Task>(config)?))
}

/// [`nominal_env`] of task `T` from its configuration table (the registry's deployment offer).
pub(crate) fn nominal_env_of<T: Task>(table: &toml::Table) -> Result<Box<dyn ArmTaskEnv>> {
    Ok(Box::new(nominal::<T>(from_table(table.clone())?)?))
}

/// Task `T`'s nominal scene from its configuration table, staged as a world (the registry's
/// offer to the twin).
pub(crate) fn world_of<T: Task>(table: &toml::Table) -> Result<Box<dyn ArmWorld>> {
    Ok(Box::new(nominal::<T>(from_table(table.clone())?)?))
}
