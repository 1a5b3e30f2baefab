//! The trained model's side of the loop: its env rebuilt from the model's settings (never
//! stepped) supplies the observation layout, the action mapping, the home pose and the object
//! facts — the same code the policy was trained through.

use crate::error::{DeployError, Result};
use fairgrasp_env::arm::{ActionMode, ArmState, Command};
use fairgrasp_env::sim::kinematics::SerialChain;
use fairgrasp_env::wrappers::RescaleAction;
use fairgrasp_env::{Env, GraspConfig, GraspEnv};
use fairgrasp_rl::policies::Policy;

/// What the deployment loop needs of the model's environment.
pub struct ModelIo {
    env: RescaleAction<GraspEnv>,
    /// Base → TCP, the chain the policy's TCP observations came from.
    pub chain: SerialChain,
    /// The state of the freshly reset env: home pose, table, object's size and rest height.
    pub nominal: ArmState,
    pub control_period: f64,
    pub max_steps: u32,
    pub limits_rad: Vec<(f32, f32)>,
}

impl ModelIo {
    /// Rebuilds the model's env. Only the grasp task can be deployed today: pick-and-place
    /// and sorting need a goal and bins from the real world, which no source provides yet.
    pub fn for_policy(policy: &Policy) -> Result<Self> {
        if policy.env_id() != fairgrasp_env::ENV_ID {
            return Err(DeployError::config(
                "model",
                format!(
                    "trained on {}; deployment supports {} (the other tasks need goals and \
                     bins from the real world)",
                    policy.env_id(),
                    fairgrasp_env::ENV_ID
                ),
            ));
        }
        let table = fairgrasp_rl::model::env_table(policy.env_config())?;
        let config: GraspConfig = fairgrasp_env::config::from_table(table)?;
        let io = Self::for_config(config)?;
        let inner = io.env.inner();
        if inner.observation_space().dim() != policy.obs_dim()
            || inner.action_space().dim() != policy.act_dim()
        {
            return Err(DeployError::config(
                "model",
                format!(
                    "its env gives {} observations and takes {} actions; the networks take {} \
                     and give {}",
                    inner.observation_space().dim(),
                    inner.action_space().dim(),
                    policy.obs_dim(),
                    policy.act_dim()
                ),
            ));
        }
        Ok(io)
    }

    /// The grasp env with these settings (the robot, its home pose and limits, the table):
    /// what the commissioning steps need when no model is given.
    pub fn for_config(config: GraspConfig) -> Result<Self> {
        let mut env = RescaleAction::new(GraspEnv::new(config)?)?;
        env.reset(Some(0))?;
        let inner = env.inner();
        let scene = inner.scene();
        let nominal = inner
            .state()
            .cloned()
            .ok_or_else(|| DeployError::Other("the model's env has no state".into()))?;
        Ok(Self {
            chain: SerialChain::new(&scene.robot().model, "tcp")?,
            control_period: scene.control_period() as f64,
            max_steps: inner.config().task.max_episode_steps,
            limits_rad: scene.arm_limits(),
            nominal,
            env,
        })
    }

    pub fn action_mode(&self) -> ActionMode {
        self.env.inner().mapper().config().action_mode
    }

    /// The observation for a state, the previous action given as the env gives it (each value
    /// divided by its bound).
    pub fn observe(&self, state: &ArmState, previous: &[f32]) -> Vec<f32> {
        self.env.inner().observation_of(state, previous)
    }

    /// The env action for a policy output (clipped into [-1, 1], rescaled to the env's
    /// units) and the previous-action values the next observation shows.
    pub fn env_action(&self, policy_output: &[f32]) -> Result<(Vec<f32>, Vec<f32>)> {
        let action = self.env.to_inner_action(policy_output)?;
        let high = &self.env.inner().action_space().high;
        let shown = action.iter().zip(high).map(|(a, h)| a / h).collect();
        Ok((action, shown))
    }

    /// The command holding the arm where `state` has it.
    pub fn hold(&self, state: &ArmState) -> Command {
        self.env.inner().mapper().hold(state, state.q.clone())
    }

    /// Applies an env action to the command; false when inverse kinematics failed (the
    /// targets were kept, as in training).
    pub fn apply(&self, state: &ArmState, action: &[f32], command: &mut Command) -> bool {
        self.env
            .inner()
            .mapper()
            .apply(state, action, command)
            .is_none()
    }
}
