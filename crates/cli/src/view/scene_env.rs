//! The environments the viewer can show: the arm tasks, built concretely so that their scene
//! (for the free camera and the joint sliders) is reachable behind one trait object.

use anyhow::{Result, bail};
use fairgrasp_env::arm::{ActionMode, ArmEnv, ArmEnvConfig, Task};
use fairgrasp_env::config::from_table;
use fairgrasp_env::core::Env;
use fairgrasp_env::tasks::{grasp::Grasp, pick_place::PickPlace, sort::Sort};
use fairgrasp_sim::scene::Scene;

/// An environment whose scene can be drawn: the arm tasks.
pub trait SceneEnv: Env {
    fn scene(&self) -> &Scene;
    /// Whether actions are joint deltas (manual mode needs them).
    fn joint_actions(&self) -> bool;
}

impl<T: Task> SceneEnv for ArmEnv<T> {
    fn scene(&self) -> &Scene {
        ArmEnv::scene(self)
    }
    fn joint_actions(&self) -> bool {
        self.config().control.action_mode == ActionMode::Joint
    }
}

fn arm<T: Task>(table: &toml::Table) -> Result<Box<dyn SceneEnv>> {
    let config: ArmEnvConfig<T::Settings, T::Reward> = from_table(table.clone())?;
    Ok(Box::new(ArmEnv::<T>::new(config)?))
}

/// Builds arm task `id` (the viewer draws a scene, so the classic-control tasks are out).
pub fn make_env(id: &str, table: &toml::Table) -> Result<Box<dyn SceneEnv>> {
    match id {
        "FaArmGrasp-v0" => arm::<Grasp>(table),
        "FaArmPickPlace-v0" => arm::<PickPlace>(table),
        "FaArmSort-v0" => arm::<Sort>(table),
        _ => bail!(
            "`fairgrasp view` shows the arm tasks (FaArmGrasp-v0, FaArmPickPlace-v0, \
             FaArmSort-v0), not {id}"
        ),
    }
}
