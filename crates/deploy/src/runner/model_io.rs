//! The trained model's side of the loop: its env rebuilt from the model's settings (never
//! stepped) supplies the observation layout, the action mapping, the home pose and the object
//! facts — the same code the policy was trained through.

use crate::error::{DeployError, Result};
use crate::safety::SafetyConfig;
use fairgrasp_env::arm::ServoConfig;
use fairgrasp_env::arm::{ActionMode, ArmState, Command, EstimatorFacts};
use fairgrasp_env::sim::kinematics::SerialChain;
use fairgrasp_env::sim::scene::ArmDrive;
use fairgrasp_env::tasks::grasp::GraspSettings;
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
    /// What the state estimator knows beyond the controller's readings.
    pub facts: EstimatorFacts,
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
    pub fn for_config(mut config: GraspConfig) -> Result<Self> {
        // The nominal world: a model trained with domain randomisation must not find its home
        // pose jittered or its object resized here (observation noise is never added outside
        // `step` anyway).
        config.randomization.enabled = false;
        let mut env = RescaleAction::new(GraspEnv::new(config)?)?;
        env.reset(Some(0))?;
        let inner = env.inner();
        let scene = inner.scene();
        let nominal = inner
            .state()
            .cloned()
            .ok_or_else(|| DeployError::Other("the model's env has no state".into()))?;
        let chain = SerialChain::new(&scene.robot().model, "tcp")?;
        Ok(Self {
            facts: EstimatorFacts::new(chain.clone(), &nominal),
            chain,
            control_period: scene.control_period() as f64,
            max_steps: inner.config().task.max_episode_steps,
            limits_rad: scene.arm_limits(),
            nominal,
            env,
        })
    }

    /// The model's `[task]` settings: the success rule ([`GraspSettings::holds`] for
    /// `success_hold_steps` control steps) that ended its training episodes.
    pub fn task(&self) -> &GraspSettings {
        &self.env.inner().config().task
    }

    /// The motion model the policy was trained through (`[control.servo]`).
    pub fn servo(&self) -> &ServoConfig {
        &self.env.inner().mapper().config().servo
    }

    /// Why the arm's motion under `safety` is not the one the policy trained on, if it is not:
    /// a model trained with targets reaching PD drives at once (neither `[control.servo]` nor
    /// the kinematic arm drive), or with other caps.
    pub fn motion_mismatch(&self, safety: &SafetyConfig) -> Option<String> {
        let servo = self.servo();
        let arm = &self.env.inner().scene().config().arm;
        // Both move the joints through the safety filter's ramp: the servo model every 8 ms, the
        // kinematic drive every physics step. With both, the servo's set points are the targets
        // the drive follows, so the tighter caps of the two are what the policy saw.
        let kinematic = (arm.drive == ArmDrive::Kinematic).then_some((
            arm.kinematic_speed_deg_s as f64,
            arm.kinematic_acc_deg_s2 as f64,
        ));
        let servoed = servo.enabled.then_some((
            servo.max_joint_speed_deg_s as f64,
            servo.max_joint_acc_deg_s2 as f64,
        ));
        let trained = match (servoed, kinematic) {
            (Some(s), Some(k)) => (s.0.min(k.0), s.1.min(k.1)),
            (Some(caps), None) | (None, Some(caps)) => caps,
            (None, None) => {
                return Some(
                    "this model was trained with targets reaching the drives at once, not through \
                     the deployment's set-point ramp; expect it to grasp less often than in \
                     simulation (train with configs/ppo_deploy.toml: docs/deployment.md)"
                        .into(),
                );
            }
        };
        let here = (safety.max_joint_speed_deg_s, safety.max_joint_acc_deg_s2);
        let differs = |a: f64, b: f64| (a - b).abs() > 1e-3 * a.abs().max(1.0);
        (differs(trained.0, here.0) || differs(trained.1, here.1)).then(|| {
            format!(
                "the model trained with caps of {} deg/s and {} deg/s²; the safety settings                  allow {} deg/s and {} deg/s² at scale 1, so the arm will not move as it learnt",
                trained.0, trained.1, here.0, here.1
            )
        })
    }

    /// Why the policy will read the arm differently from how it learnt, if it will: a model
    /// trained on the simulator's true state (without `[readings]`) saw true pad contacts and
    /// exact openings that the deployment only infers.
    pub fn observation_mismatch(&self) -> Option<String> {
        (!self.env.inner().config().readings.enabled).then(|| {
            "this model observed the simulator's true state in training, not the controller's \
             readings the deployment builds its observation from (pad contacts, the gripper in \
             whole percent, the object's feed); expect it to grasp less often than in simulation \
             (train with configs/ppo_deploy.toml: docs/deployment.md)"
                .into()
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

#[cfg(test)]
mod tests {
    use super::*;
    use fairgrasp_env::GraspConfig;

    #[test]
    fn a_model_trained_without_the_servo_model_or_with_other_caps_is_flagged() {
        let safety = SafetyConfig::default();
        let plain = ModelIo::for_config(GraspConfig::default()).unwrap();
        assert!(
            plain
                .motion_mismatch(&safety)
                .unwrap()
                .contains("ppo_deploy")
        );
        let mut config = GraspConfig::default();
        config.control.servo.enabled = true;
        let servoed = ModelIo::for_config(config).unwrap();
        assert_eq!(servoed.motion_mismatch(&safety), None);
        let gentler = SafetyConfig {
            max_joint_acc_deg_s2: 300.0,
            // The speed scale is not a mismatch: it slows the same motion in time.
            speed_scale: 0.1,
            ..SafetyConfig::default()
        };
        assert!(servoed.motion_mismatch(&gentler).unwrap().contains("300"));
        // The kinematic arm drive moves through the same ramp, with its own caps.
        let mut config = GraspConfig::default();
        config.scene.arm.drive = ArmDrive::Kinematic;
        let kinematic = ModelIo::for_config(config.clone()).unwrap();
        assert_eq!(kinematic.motion_mismatch(&safety), None);
        config.scene.arm.kinematic_acc_deg_s2 = 2000.0;
        let snappier = ModelIo::for_config(config).unwrap();
        assert!(snappier.motion_mismatch(&safety).unwrap().contains("2000"));
    }

    #[test]
    fn a_model_trained_with_randomisation_deploys_from_the_nominal_home() {
        let nominal = ModelIo::for_config(GraspConfig::default()).unwrap();
        let mut config = GraspConfig::default();
        config.randomization.enabled = true;
        config.randomization.initial_joint_jitter = 0.05;
        config.randomization.object_scale = [0.5, 0.6];
        let randomised = ModelIo::for_config(config).unwrap();
        assert_eq!(randomised.nominal.q, nominal.nominal.q);
        assert_eq!(
            randomised.nominal.objects[0].rest_z,
            nominal.nominal.objects[0].rest_z
        );
    }
}
