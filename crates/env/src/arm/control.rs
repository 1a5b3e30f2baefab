//! From an action to joint targets: one component, fed by an [`ArmState`], shared by the
//! simulated environments and the deployment loop on the real arm.
//!
//! Joint mode adds the action's deltas to the held joint targets; Cartesian mode moves a
//! commanded top-down TCP pose and solves inverse kinematics for it. Both keep the targets
//! within a few steps of the measured joints (the lead cap) and the joint limits; Cartesian mode
//! also keeps the commanded TCP inside a workspace box.

use crate::arm::drives::DrivesConfig;
use crate::arm::gripper::GripperConfig;
use crate::arm::servo::ServoConfig;
use crate::arm::state::ArmState;
use crate::error::{EnvError, Result};
use crate::spaces::BoxSpace;
use fairgrasp_sim::kinematics::SerialChain;
use fairgrasp_sim::rapier3d::na::{Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// What an action commands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionMode {
    /// Joint-angle deltas (rad) and a gripper command.
    Joint,
    /// TCP deltas (dx, dy, dz in m, dyaw in rad) with the tool pointing down, and a gripper
    /// command; joint targets come from inverse kinematics.
    Cartesian,
}

/// How actions become joint targets.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControlConfig {
    /// What an action commands: joint deltas or TCP deltas.
    pub action_mode: ActionMode,
    /// Largest joint-angle change per control step (rad). The design used 0.1 and recommends
    /// 0.05 for smoother motion.
    pub max_joint_delta: f32,
    /// Largest TCP translation per control step in Cartesian mode (m).
    pub max_tcp_delta: f32,
    /// Largest TCP yaw change per control step in Cartesian mode (rad).
    pub max_yaw_delta: f32,
    /// Joint targets never run more than this many steps of `max_joint_delta` ahead of the
    /// measured angles, so a blocked arm does not wind up.
    pub lead_steps: f32,
    /// Cartesian mode: the commanded TCP stays in this box, arm base frame (m).
    pub workspace_min: [f32; 3],
    /// Cartesian mode: the upper corner of that box, above `workspace_min` on every axis (m).
    pub workspace_max: [f32; 3],
    /// The deployment's motion model: joint targets reach the drives through speed- and
    /// acceleration-capped set points every servo period ([`crate::arm::servo`]).
    pub servo: ServoConfig,
    /// The gripper's controller: the fingers move through its set point
    /// ([`crate::arm::gripper`]).
    pub gripper: GripperConfig,
    /// The arm's drives between the servo set points and the joints: a delay and a lag per
    /// joint, as `fairgrasp sysid` identifies them ([`crate::arm::drives`]).
    pub drives: DrivesConfig,
    /// The deployment's speed scales the policy will run at, one drawn per episode (no draw
    /// for one value). At scale s a control step lasts its period over s of simulated time
    /// (physics substeps ÷ s) with the servo caps, the gripper's speed and the reported speeds
    /// scaled as the deployment scales them: the arm's motion is the same in the policy's time,
    /// while the drives' lag, the fingers' force and the object's inertia act in the
    /// simulator's, as on the arm. Physics costs the mean of 1/s. Below 1 it needs
    /// `[readings]`, which reads speeds in the policy's time.
    pub speed_scales: Vec<f32>,
    /// The observation ends with the episode's speed scale (the deployment passes its own):
    /// at scale s the drives lag, the fingers close and the object moves 1/s times faster in
    /// the policy's time, so a policy that sees s can act for the arm it drives. Off (the
    /// default): one behaviour for every scale.
    pub observe_speed_scale: bool,
    /// A cobot's collision detection (N): the episode ends, failed with
    /// [`EpisodeEvent::Collision`](crate::core::EpisodeEvent::Collision), when a robot link
    /// presses on an object, the table or a bin with more than this force in any physics step.
    /// Unset (the default): nothing is watched.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub collision_force_limit: Option<f32>,
    /// What pressing costs, so that a policy learns to stay under a controller's collision
    /// detection without its episodes ending while it explores: each step,
    /// `collision_penalty · min(F / collision_penalty_force, 4)` is subtracted (reward term
    /// `press`), with F the largest net external force on the robot that the collision sensor
    /// read in the step (`contact_force`). A grasp's squeeze is internal and costs nothing; a
    /// held cube's weight next to nothing. 0 (the default): pressing is free.
    pub collision_penalty: f32,
    /// The force (N) that costs `collision_penalty` per step.
    pub collision_penalty_force: f32,
}

impl Default for ControlConfig {
    fn default() -> Self {
        Self {
            action_mode: ActionMode::Joint,
            max_joint_delta: 0.05,
            max_tcp_delta: 0.02,
            max_yaw_delta: 0.1,
            lead_steps: 3.0,
            // The placement area (0.3…0.7, −0.2…0.2) with a 15 cm margin, from 1.5 cm above the
            // table top (the base stands on it) to 45 cm.
            workspace_min: [0.15, -0.35, 0.015],
            workspace_max: [0.85, 0.35, 0.45],
            servo: ServoConfig::default(),
            gripper: GripperConfig::default(),
            drives: DrivesConfig::default(),
            speed_scales: vec![1.0],
            observe_speed_scale: false,
            collision_force_limit: None,
            collision_penalty: 0.0,
            collision_penalty_force: 150.0,
        }
    }
}

impl ControlConfig {
    /// Checks every range; errors name the key (`control.…`).
    pub fn validate(&self) -> Result<()> {
        let positive = |key: &str, v: f32, max: f32| {
            if v.is_finite() && v > 0.0 && v <= max {
                Ok(())
            } else {
                Err(EnvError::config(
                    key,
                    format!("must be in (0, {max}], got {v}"),
                ))
            }
        };
        positive("control.max_joint_delta", self.max_joint_delta, 0.5)?;
        positive("control.max_tcp_delta", self.max_tcp_delta, 0.1)?;
        positive("control.max_yaw_delta", self.max_yaw_delta, 0.5)?;
        positive("control.lead_steps", self.lead_steps, 20.0)?;
        self.gripper.validate()?;
        self.drives.validate(self.servo.enabled)?;
        let scales = &self.speed_scales;
        if scales.is_empty() || scales.len() > 16 {
            return Err(EnvError::config(
                "control.speed_scales",
                format!("must list 1 to 16 scales, got {}", scales.len()),
            ));
        }
        for &v in scales {
            positive("control.speed_scales", v, 1.0)?;
            if v < 0.05 {
                return Err(EnvError::config(
                    "control.speed_scales",
                    format!("each scale must be at least 0.05 (physics ÷ 20), got {v}"),
                ));
            }
        }
        if let Some(limit) = self.collision_force_limit {
            positive("control.collision_force_limit", limit, 1e5)?;
        }
        if !(self.collision_penalty.is_finite() && (0.0..=100.0).contains(&self.collision_penalty))
        {
            return Err(EnvError::config(
                "control.collision_penalty",
                format!("must be in [0, 100], got {}", self.collision_penalty),
            ));
        }
        positive(
            "control.collision_penalty_force",
            self.collision_penalty_force,
            1e5,
        )?;
        positive("control.servo.period_ms", self.servo.period_ms, 100.0)?;
        positive(
            "control.servo.max_joint_speed_deg_s",
            self.servo.max_joint_speed_deg_s,
            1000.0,
        )?;
        positive(
            "control.servo.max_joint_acc_deg_s2",
            self.servo.max_joint_acc_deg_s2,
            1e6,
        )?;
        for k in 0..3 {
            let (lo, hi) = (self.workspace_min[k], self.workspace_max[k]);
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(EnvError::config(
                    "control.workspace_min",
                    format!(
                        "must be below control.workspace_max on every axis (axis {k}: {lo} vs {hi})"
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// What the arm is commanded to do: the controller's memory between steps.
#[derive(Clone, Debug, PartialEq)]
pub struct Command {
    /// Joint position targets (rad).
    pub arm_target: Vec<f32>,
    /// Cartesian mode: the commanded TCP pose (base frame).
    pub tcp_target: Isometry3<f64>,
    /// Whether the gripper is commanded open.
    pub gripper_open: bool,
}

/// Why an action could not be carried out in full.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MappingEvent {
    /// Inverse kinematics found no joints for the commanded pose; the targets were kept.
    IkFailed,
    /// Cartesian mode: the commanded yaw lies beyond the wrist's reach; the TCP moved to the
    /// commanded position pointing down, its yaw as far as the joints go.
    YawLimited,
}

/// Maps actions to joint targets (see the [module](self) documentation).
#[derive(Clone, Debug)]
pub struct ActionMapper {
    config: ControlConfig,
    chain: SerialChain,
    limits: Vec<(f32, f32)>,
}

/// A TCP pose pointing straight down at `position` with the fingers closing along `yaw`.
pub fn top_down_pose(position: Vector3<f64>, yaw: f64) -> Isometry3<f64> {
    let down = UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0);
    let rotation = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw) * down;
    Isometry3::from_parts(Translation3::from(position), rotation)
}

impl ActionMapper {
    /// `chain` is the arm's kinematic chain from its base to the TCP; `limits` its joint limits.
    pub fn new(config: ControlConfig, chain: SerialChain, limits: Vec<(f32, f32)>) -> Result<Self> {
        config.validate()?;
        if chain.dof() != limits.len() {
            return Err(EnvError::Usage(format!(
                "the chain has {} joints but {} limits were given",
                chain.dof(),
                limits.len()
            )));
        }
        Ok(Self {
            config,
            chain,
            limits,
        })
    }

    /// The control settings it maps by.
    pub fn config(&self) -> &ControlConfig {
        &self.config
    }

    /// Number of arm joints.
    pub fn dof(&self) -> usize {
        self.limits.len()
    }

    /// The action space: joint deltas or TCP deltas, then the gripper command (> 0 opens).
    pub fn action_space(&self) -> BoxSpace {
        let c = &self.config;
        let (mut low, mut high) = match c.action_mode {
            ActionMode::Joint => (
                vec![-c.max_joint_delta; self.dof()],
                vec![c.max_joint_delta; self.dof()],
            ),
            ActionMode::Cartesian => {
                let (p, y) = (c.max_tcp_delta, c.max_yaw_delta);
                (vec![-p, -p, -p, -y], vec![p, p, p, y])
            }
        };
        low.push(-1.0);
        high.push(1.0);
        BoxSpace::new(low, high)
    }

    /// The TCP pose (arm base frame) at joint angles `q` by the kinematic model: what a
    /// controller reports for the angles its encoders read.
    pub fn forward(&self, q: &[f32]) -> Isometry3<f64> {
        let q: Vec<f64> = q.iter().map(|&v| v as f64).collect();
        self.chain.forward(&q)
    }

    /// What the action's values mean, for error messages.
    pub fn layout(&self) -> String {
        match self.config.action_mode {
            ActionMode::Joint => format!("{} joint-angle deltas and a gripper command", self.dof()),
            ActionMode::Cartesian => "dx, dy, dz, dyaw and a gripper command".into(),
        }
    }

    /// The command that holds the arm where it is: the current joint targets, a top-down TCP
    /// target at the current TCP position and yaw, gripper open.
    pub fn hold(&self, state: &ArmState, arm_target: Vec<f32>) -> Command {
        let yaw = state.tcp.rotation.euler_angles().2;
        Command {
            arm_target,
            tcp_target: top_down_pose(state.tcp.translation.vector, yaw),
            gripper_open: true,
        }
    }

    /// Applies one action (already clipped to the action space) to `command`.
    pub fn apply(
        &self,
        state: &ArmState,
        action: &[f32],
        command: &mut Command,
    ) -> Option<MappingEvent> {
        command.gripper_open = *action.last().expect("the action space has a gripper entry") > 0.0;
        match self.config.action_mode {
            ActionMode::Joint => {
                // Targets accumulate (a zero action holds the pose instead of letting it sag),
                // but never run more than `lead_steps` steps ahead of the measured angle.
                let lead = self.config.lead_steps * self.config.max_joint_delta;
                for (i, target) in command.arm_target.iter_mut().enumerate() {
                    let q = state.q[i];
                    let t = (*target + action[i]).clamp(q - lead, q + lead);
                    *target = t.clamp(self.limits[i].0, self.limits[i].1);
                }
                None
            }
            ActionMode::Cartesian => {
                let delta = Vector3::new(action[0] as f64, action[1] as f64, action[2] as f64);
                let mut target = command.tcp_target;
                target.translation.vector += delta;
                target.rotation =
                    UnitQuaternion::from_euler_angles(0.0, 0.0, action[3] as f64) * target.rotation;
                let (lo, hi) = (self.config.workspace_min, self.config.workspace_max);
                for k in 0..3 {
                    target.translation.vector[k] =
                        target.translation.vector[k].clamp(lo[k] as f64, hi[k] as f64);
                }
                let seed: Vec<f64> = command.arm_target.iter().map(|&v| v as f64).collect();
                if let Ok(q) = self.chain.inverse(&target, &seed, 1e-4) {
                    command.arm_target = q.into_iter().map(|v| v as f32).collect();
                    command.tcp_target = target;
                    return None;
                }
                // A yaw beyond the wrist's limit must not freeze the arm: the policy sees the
                // TCP's yaw, not the target's, and would keep asking for a move never made.
                match self.chain.inverse_free_yaw(&target, &seed, 1e-4) {
                    Ok(q) => {
                        let reached = self.chain.forward(&q);
                        let yaw_gap = (reached.rotation * target.rotation.inverse())
                            .scaled_axis()
                            .z;
                        target.rotation =
                            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_gap) * target.rotation;
                        command.arm_target = q.into_iter().map(|v| v as f32).collect();
                        command.tcp_target = target;
                        Some(MappingEvent::YawLimited)
                    }
                    Err(_) => Some(MappingEvent::IkFailed),
                }
            }
        }
    }
}
