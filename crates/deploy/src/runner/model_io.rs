//! The trained model's side of the loop: its env rebuilt from the model's settings (never
//! stepped) supplies the observation layout, the action mapping, the home pose, the object
//! facts and the task's success rule — the same code the policy was trained through. The env
//! registry builds it from the model's env id ([`fairgrasp_env::registry::ArmOffer`]), so the
//! loop serves whichever task the registry offers for deployment.

use crate::calibration::{Calibration, CameraPose};
use crate::error::{DeployError, Result};
use crate::kinematics::ArmKinematics;
use crate::safety::SafetyConfig;
use fairgrasp_env::Env;
use fairgrasp_env::arm::camera::CameraObsConfig;
use fairgrasp_env::arm::erased::nominal_env;
use fairgrasp_env::arm::{
    ActionMode, ArmState, Command, EstimatorFacts, MappingEvent, SuccessJudge,
};
use fairgrasp_env::arm::{ArmEnvConfig, ArmTaskEnv, ServoConfig, Task, TaskSettings};
use fairgrasp_env::registry;
use fairgrasp_env::sim::envelope::Envelope;
use fairgrasp_env::sim::kinematics::SerialChain;
use fairgrasp_env::sim::scene::ArmDrive;
use fairgrasp_env::wrappers::RescaleAction;
use fairgrasp_rl::Policy;

/// What the deployment loop needs of the model's environment.
pub struct ModelIo {
    env: RescaleAction<Box<dyn ArmTaskEnv>>,
    /// Base → TCP, the chain the policy's TCP observations came from.
    pub chain: SerialChain,
    /// Spheres covering the arm's and gripper's shapes, for the safety layer's clearance.
    pub envelope: Envelope,
    /// The state of the freshly reset env: home pose, table, object's size and rest height.
    pub nominal: ArmState,
    /// What the state estimator knows beyond the controller's readings.
    pub facts: EstimatorFacts,
    /// The simulator's control period (s): the time one policy action lasts.
    pub control_period: f64,
    /// Control steps before the model's episodes were truncated in training.
    pub max_steps: u32,
    /// The cameras a camera policy learnt with (`None`: the policy reads no images).
    pub camera: Option<CameraObsConfig>,
    /// `(lower, upper)` joint limits of the arm (rad, the simulator's joints).
    pub limits_rad: Vec<(f32, f32)>,
}

impl ModelIo {
    /// Rebuilds the model's env. Only the tasks the registry offers for deployment can be
    /// deployed (the grasp task today: pick-and-place and sorting need a goal and bins from the
    /// real world, which no source provides yet).
    pub fn for_policy(policy: &Policy) -> Result<Self> {
        let table = fairgrasp_rl::model::env_table(policy.env_config())?;
        let mut io = Self::for_env(policy.env_id(), &table)?;
        if policy.image_space().is_some() {
            let camera = (table.get("camera").cloned())
                .unwrap_or_else(|| toml::Value::Table(toml::Table::new()));
            io.camera =
                Some(camera.try_into().map_err(|e| {
                    DeployError::config("model", format!("its camera settings: {e}"))
                })?);
        }
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

    /// Env `env_id` with the settings `table`, as the registry offers it for deployment.
    pub fn for_env(env_id: &str, table: &toml::Table) -> Result<Self> {
        let offer = registry::arm_offer(env_id).and_then(|a| a.deployment);
        let Some(build) = offer else {
            return Err(DeployError::config(
                "model",
                format!(
                    "trained on {env_id}; deployment supports {} (the other tasks need goals \
                     and bins from the real world)",
                    registry::deployable_ids().join(", ")
                ),
            ));
        };
        Self::nominal(build(table)?)
    }

    /// The env of a typed arm-task configuration (the robot, its home pose and limits, the
    /// table): what the commissioning steps need when no model is given.
    pub fn for_config<S: TaskSettings>(
        config: ArmEnvConfig<S, <S::Task as Task>::Reward>,
    ) -> Result<Self> {
        Self::nominal(nominal_env(config)?)
    }

    /// `env` (built without randomisation) at its nominal state: a model trained with domain
    /// randomisation must not find its home pose jittered or its object resized here
    /// (observation noise is never added outside `step` anyway).
    fn nominal(env: Box<dyn ArmTaskEnv>) -> Result<Self> {
        if env.success_judge().is_none() {
            return Err(DeployError::config(
                "model",
                "its task's success needs the simulator; the deployment judges the arm's states",
            ));
        }
        let mut env = RescaleAction::new(env)?;
        env.reset(Some(0))?;
        let inner = env.inner();
        let scene = inner.scene();
        let nominal = inner
            .state()
            .cloned()
            .ok_or_else(|| DeployError::Other("the model's env has no state".into()))?;
        let chain = SerialChain::new(&scene.robot().model, "tcp")?;
        let envelope = Envelope::new(&scene.robot().model, "tcp")?;
        Ok(Self {
            facts: EstimatorFacts::new(chain.clone(), &nominal),
            chain,
            envelope,
            control_period: scene.control_period() as f64,
            max_steps: inner.max_episode_steps(),
            limits_rad: scene.arm_limits(),
            camera: None,
            nominal,
            env,
        })
    }

    /// The arm's forward kinematics in the robot's units under `calibration`, for the safety
    /// filter.
    pub fn arm_kinematics(&self, calibration: &Calibration) -> ArmKinematics {
        ArmKinematics::new(self.envelope.clone(), calibration.clone())
    }

    /// The task's success rule, fresh for an episode: the rule that ended the model's training
    /// episodes, applied to the states the deployment estimates.
    pub fn success_judge(&self) -> Box<dyn SuccessJudge> {
        // Checked in `nominal`: every ModelIo's task judges states alone.
        (self.env.inner().success_judge()).expect("checked when the ModelIo was built")
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
                "the model trained with caps of {} deg/s and {} deg/s²; the safety settings \
                 allow {} deg/s and {} deg/s² at scale 1, so the arm will not move as it learnt",
                trained.0, trained.1, here.0, here.1
            )
        })
    }

    /// Why the gripper will not move as the policy learnt, if it will not: a model trained with
    /// the fingers' target jumping (without `[control.gripper]`) meets a `MoveGripper` whose set
    /// point ramps.
    pub fn gripper_mismatch(&self) -> Option<String> {
        (!self.env.inner().mapper().config().gripper.enabled).then(|| {
            "this model was trained with the fingers' target jumping to open or closed, not \
             through the gripper's MoveGripper ramp; two of five such policies grasped 50 % and \
             86 % of deployment-matched episodes at scale 1 (train with configs/ppo_deploy.toml)"
                .into()
        })
    }

    /// Why the arm's dynamics will not be the ones the policy learnt, if they will not: the
    /// speed scale slows the set points but not the drives' lag, the fingers' force or the
    /// object's inertia, so a model trained at other scales (`control.speed_scales`) meets
    /// another timescale.
    pub fn speed_scale_mismatch(&self, safety: &SafetyConfig) -> Option<String> {
        let trained = &self.env.inner().mapper().config().speed_scales;
        let here = safety.speed_scale;
        let near = |&s: &f32| (s as f64 - here).abs() <= 1e-3 * here;
        (!trained.iter().any(near)).then(|| {
            let listed: Vec<String> = trained.iter().map(|s| s.to_string()).collect();
            format!(
                "the model trained at speed scale {} and runs at {here}: the drives' lag, the \
                 fingers and the object act on another timescale than it learnt (trained at 1 \
                 alone, fresh policies grasped 92-98.5 % of deployment-matched episodes at 0.25 \
                 against 97.5-100 % at 1); list the scale in control.speed_scales \
                 (configs/ppo_deploy.toml)",
                listed.join(", ")
            )
        })
    }

    /// Why the policy will read the arm differently from how it learnt, if it will: a model
    /// trained on the simulator's true state (without `[readings]`) saw true pad contacts and
    /// exact openings that the deployment only infers.
    pub fn observation_mismatch(&self) -> Option<String> {
        (!self.env.inner().readings().enabled).then(|| {
            "this model observed the simulator's true state in training, not the controller's \
             readings the deployment builds its observation from (pad contacts, the gripper in \
             whole percent, the object's feed); expect it to grasp less often than in simulation \
             (train with configs/ppo_deploy.toml: docs/deployment.md)"
                .into()
        })
    }

    /// Why the cell's camera (the calibration file's `[camera]`) will not see the scene as
    /// the camera policy learnt to, if it will not: its position, direction or field of view
    /// outside the training's randomisation (5 mm, 1° without it), or no pose given.
    pub fn camera_mismatch(&self, calibration: &Calibration) -> Option<String> {
        let trained = self.camera.as_ref()?;
        if !trained.scene.enabled {
            return None;
        }
        let s = &trained.scene;
        let Some(cell) = &calibration.camera else {
            return Some(format!(
                "the calibration file gives no [camera] pose: check that the scene camera sits \
                 where the model's did (eye {:?} m, looking at {:?} m, field of view {}°)",
                s.eye, s.target, s.fov_deg
            ));
        };
        let model = CameraPose {
            eye: s.eye.map(f64::from),
            target: s.target.map(f64::from),
            fov_deg: s.fov_deg as f64,
        };
        let moved = (0..3)
            .map(|i| (cell.eye[i] - model.eye[i]).abs())
            .fold(0.0, f64::max);
        let (a, b) = (cell.direction(), model.direction());
        let cos = (0..3).map(|i| a[i] * b[i]).sum::<f64>().clamp(-1.0, 1.0);
        let turned = cos.acos().to_degrees();
        let wider = (cell.fov_deg - model.fov_deg).abs();
        pose_problems(trained, moved, turned, wider).map(|problems| {
            format!("the cell's camera is not where the model learnt to see from: {problems}")
        })
    }

    /// Why the cell's wrist camera (the calibration file's `[wrist_camera]`) will not see as
    /// the camera policy's did, if it will not: its offset from the TCP, its direction (the
    /// model's looks along the tool's z) or field of view outside the training's randomisation
    /// (5 mm, 1° without it), or no mounting given.
    pub fn wrist_camera_mismatch(&self, calibration: &Calibration) -> Option<String> {
        let trained = self.camera.as_ref()?;
        if !trained.wrist.enabled {
            return None;
        }
        let w = &trained.wrist;
        let Some(cell) = &calibration.wrist_camera else {
            return Some(format!(
                "the calibration file gives no [wrist_camera] mounting: check that the wrist \
                 camera sits where the model's did (offset {:?} m in the TCP frame, looking \
                 along the tool's z, field of view {}°)",
                w.offset, w.fov_deg
            ));
        };
        let moved = (0..3)
            .map(|i| (cell.offset[i] - w.offset[i] as f64).abs())
            .fold(0.0, f64::max);
        let turned = cell.unit_direction()[2]
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        let wider = (cell.fov_deg - w.fov_deg as f64).abs();
        pose_problems(trained, moved, turned, wider).map(|problems| {
            format!(
                "the cell's wrist camera is not mounted where the model learnt to see from: \
                 {problems}"
            )
        })
    }

    /// How the policy's actions command the arm: joint deltas or TCP deltas.
    pub fn action_mode(&self) -> ActionMode {
        self.env.inner().mapper().config().action_mode
    }

    /// The observation for a state at the deployment's speed scale, the previous action given
    /// as the env gives it (each value divided by its bound).
    pub fn observe(&self, state: &ArmState, previous: &[f32], speed_scale: f64) -> Vec<f32> {
        (self.env.inner()).observation_of(state, previous, speed_scale as f32)
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
        self.env.inner().mapper().apply(state, action, command) != Some(MappingEvent::IkFailed)
    }
}

/// A mounted camera's distance from the model's (`moved`, m along the worst axis), the angle
/// between their directions and the difference of their fields of view (degrees), against the
/// training's camera randomisation (5 mm, 1° and 1° for a model trained without it): the
/// problems, if any.
fn pose_problems(trained: &CameraObsConfig, moved: f64, turned: f64, wider: f64) -> Option<String> {
    let r = &trained.randomize;
    let (position, angle, fov) = if r.enabled {
        (
            r.position_jitter as f64,
            r.angle_jitter_deg as f64,
            r.fov_jitter_deg as f64,
        )
    } else {
        (0.005, 1.0, 1.0)
    };
    let mut problems = Vec::new();
    if moved > position {
        problems.push(format!(
            "it sits {:.0} mm from the model's camera along an axis (trained within {:.0} mm)",
            moved * 1000.0,
            position * 1000.0
        ));
    }
    if turned > angle {
        problems.push(format!(
            "it looks {turned:.1}° away from the model's direction (trained within {angle}°)"
        ));
    }
    if wider > fov {
        problems.push(format!(
            "its field of view differs by {wider:.1}° (trained within {fov}°)"
        ));
    }
    (!problems.is_empty()).then(|| problems.join("; "))
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
    fn a_model_trained_with_a_jumping_finger_target_is_flagged() {
        let plain = ModelIo::for_config(GraspConfig::default()).unwrap();
        assert!(plain.gripper_mismatch().unwrap().contains("MoveGripper"));
        let mut config = GraspConfig::default();
        config.control.gripper.enabled = true;
        let ramped = ModelIo::for_config(config).unwrap();
        assert_eq!(ramped.gripper_mismatch(), None);
    }

    #[test]
    fn a_model_trained_at_other_speed_scales_is_flagged() {
        let at = |scale| SafetyConfig {
            speed_scale: scale,
            ..SafetyConfig::default()
        };
        let plain = ModelIo::for_config(GraspConfig::default()).unwrap();
        assert_eq!(plain.speed_scale_mismatch(&at(1.0)), None);
        let why = plain.speed_scale_mismatch(&at(0.25)).unwrap();
        assert!(why.contains("speed scale 1 and runs at 0.25"), "{why}");
        let mut config = GraspConfig::default();
        config.readings.enabled = true;
        config.control.speed_scales = vec![0.25, 1.0];
        let mixed = ModelIo::for_config(config).unwrap();
        assert_eq!(mixed.speed_scale_mismatch(&at(0.25)), None);
        assert!(mixed.speed_scale_mismatch(&at(0.5)).is_some());
    }

    #[test]
    fn only_the_tasks_the_registry_offers_for_deployment_are_deployed() {
        let table = toml::Table::new();
        assert!(ModelIo::for_env("FaArmGrasp-v0", &table).is_ok());
        for id in ["FaArmPickPlace-v0", "Pendulum-v1", "NoSuchEnv-v0"] {
            let e = ModelIo::for_env(id, &table).err().unwrap().to_string();
            assert!(
                e.contains(id) && e.contains("supports FaArmGrasp-v0"),
                "{e}"
            );
        }
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
