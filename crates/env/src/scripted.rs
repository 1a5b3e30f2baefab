//! A scripted pick that acts only through [`Env::step`](crate::Env::step): the proof that a
//! task can be solved with the environment's own actions, in joint and Cartesian mode.
//!
//! It is privileged (it reads the object pose from the simulator) and plans like the scene's
//! scripted pick: above the object, fingers aligned, descend, close, lift, hold — or, given a
//! goal, carry the object there and hold it.

use crate::arm::{ActionMode, ArmEnv, Task};
use fairgrasp_sim::rapier3d::na::{Isometry3, Translation3, Vector3};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Approach,
    Descend,
    Close,
    Lift,
    Carry,
    Hold,
    /// Open over the goal and wait for the object to drop (sorting).
    Release,
    Done,
}

/// A scripted top-down grasp, one action per control step.
#[derive(Clone, Debug)]
pub struct ScriptedGraspPolicy {
    phase: Phase,
    steps_in_phase: u32,
    pre: Isometry3<f64>,
    grasp: Isometry3<f64>,
    lifted: Isometry3<f64>,
    /// Pick and place: the TCP pose that puts the object's centre on the goal.
    placed: Option<Isometry3<f64>>,
    /// Open the gripper once over the goal.
    release: bool,
    /// The pose being tracked (moves towards the phase's goal by at most `speed` per step).
    commanded: Isometry3<f64>,
}

/// Largest TCP travel per control step of the commanded pose (m).
const SPEED: f64 = 0.02;
const APPROACH_HEIGHT: f64 = 0.10;
const LIFT_HEIGHT: f64 = 0.12;
const CLOSE_STEPS: u32 = 10;
const RELEASE_STEPS: u32 = 15;

impl ScriptedGraspPolicy {
    /// Plans a pick of object 0 for the episode that `env` has just been reset to.
    pub fn new<T: Task>(env: &ArmEnv<T>) -> Self {
        Self::with_goal(env, None)
    }

    /// Plans a pick of object 0 and, with a `goal` (world frame), a carry that brings the
    /// object's centre there.
    pub fn with_goal<T: Task>(env: &ArmEnv<T>, goal: Option<Vector3<f64>>) -> Self {
        Self::for_object(env, 0, goal, false)
    }

    /// Plans a pick of object `i`, a carry of its centre to `goal` (world frame) if given, and
    /// with `release`, opening the gripper there (dropping it into a bin).
    pub fn for_object<T: Task>(
        env: &ArmEnv<T>,
        i: usize,
        goal: Option<Vector3<f64>>,
        release: bool,
    ) -> Self {
        let scene = env.scene();
        let object = scene.object_state(i).pose;
        let yaw = scene.grasp_yaw(&object.rotation);
        let centre = object.translation.vector;
        let pose = |offset: f64| scene.top_down_pose(centre + Vector3::new(0.0, 0.0, offset), yaw);
        Self {
            phase: Phase::Approach,
            steps_in_phase: 0,
            pre: pose(APPROACH_HEIGHT),
            grasp: pose(0.0),
            lifted: pose(LIFT_HEIGHT),
            placed: goal.map(|g| {
                // The TCP holds the object where it grasped it: at its centre.
                scene.top_down_pose(g, yaw)
            }),
            release,
            commanded: scene.tcp_pose(),
        }
    }

    fn goal(&self) -> Isometry3<f64> {
        match self.phase {
            Phase::Approach => self.pre,
            Phase::Descend | Phase::Close => self.grasp,
            Phase::Lift => self.lifted,
            Phase::Carry | Phase::Hold | Phase::Release | Phase::Done => {
                self.placed.unwrap_or(self.lifted)
            }
        }
    }

    fn gripper(&self) -> f32 {
        match self.phase {
            Phase::Approach | Phase::Descend | Phase::Release | Phase::Done => 1.0,
            _ => -1.0,
        }
    }

    /// Moves the commanded pose towards the goal; the approach goes in one jump since joint
    /// mode interpolates in joint space anyway.
    fn advance_commanded(&mut self) {
        let goal = self.goal();
        let delta = goal.translation.vector - self.commanded.translation.vector;
        let step = if self.phase == Phase::Approach {
            delta
        } else {
            delta * (SPEED / delta.norm().max(SPEED))
        };
        self.commanded = Isometry3::from_parts(
            Translation3::from(self.commanded.translation.vector + step),
            goal.rotation,
        );
    }

    fn update_phase<T: Task>(&mut self, env: &ArmEnv<T>) {
        self.steps_in_phase += 1;
        let tcp = env.scene().tcp_pose();
        let goal = self.goal();
        let reached = (tcp.translation.vector - goal.translation.vector).norm() < 0.01
            && (goal.rotation * tcp.rotation.inverse()).angle() < 0.05;
        let next = match self.phase {
            Phase::Approach if reached => Some(Phase::Descend),
            Phase::Descend if reached => Some(Phase::Close),
            Phase::Close if self.steps_in_phase >= CLOSE_STEPS => Some(Phase::Lift),
            Phase::Lift if reached && self.placed.is_some() => Some(Phase::Carry),
            Phase::Lift | Phase::Carry if reached => Some(Phase::Hold),
            Phase::Hold if self.release => Some(Phase::Release),
            Phase::Release if self.steps_in_phase >= RELEASE_STEPS => Some(Phase::Done),
            _ => None,
        };
        if let Some(next) = next {
            self.phase = next;
            self.steps_in_phase = 0;
        }
    }

    /// Whether a releasing plan has dropped its object.
    pub fn done(&self) -> bool {
        self.phase == Phase::Done
    }

    /// The next action for `env` (in its action space, before any rescaling wrapper).
    pub fn act<T: Task>(&mut self, env: &ArmEnv<T>) -> Vec<f32> {
        self.update_phase(env);
        self.advance_commanded();
        let gripper = self.gripper();
        let scene = env.scene();
        let control = &env.config().control;
        match control.action_mode {
            ActionMode::Joint => {
                let max = control.max_joint_delta;
                let current = env
                    .command()
                    .map(|c| c.arm_target.clone())
                    .unwrap_or_else(|| scene.arm_targets());
                let desired = scene
                    .solve_ik(&self.commanded, &current)
                    .unwrap_or_else(|_| current.clone());
                // Scale the joint step as a whole (not joint by joint) so the TCP keeps to the
                // planned line when one joint saturates.
                let largest = desired
                    .iter()
                    .zip(&current)
                    .map(|(d, c)| (d - c).abs())
                    .fold(0.0f32, f32::max);
                let scale = if largest > max { max / largest } else { 1.0 };
                let mut action: Vec<f32> = desired
                    .iter()
                    .zip(&current)
                    .map(|(d, c)| ((d - c) * scale).clamp(-max, max))
                    .collect();
                action.push(gripper);
                action
            }
            ActionMode::Cartesian => {
                let t = control;
                let base = scene.base_pose();
                let target = env
                    .command()
                    .map(|c| base * c.tcp_target)
                    .unwrap_or_else(|| scene.tcp_pose());
                let delta = base.inverse().rotation
                    * (self.commanded.translation.vector - target.translation.vector);
                let yaw_error = (self.commanded.rotation * target.rotation.inverse())
                    .euler_angles()
                    .2;
                let p = t.max_tcp_delta as f64;
                vec![
                    delta.x.clamp(-p, p) as f32,
                    delta.y.clamp(-p, p) as f32,
                    delta.z.clamp(-p, p) as f32,
                    (yaw_error as f32).clamp(-t.max_yaw_delta, t.max_yaw_delta),
                    gripper,
                ]
            }
        }
    }
}
