//! `FaArmGrasp-v0`: pick up the cube with the simulated FR5.

use crate::config::{ActionMode, EnvConfig, ObservationPreset, RewardKind};
use crate::core::{
    Env, EpisodeEvent, EpisodeParams, Frame, Info, Metadata, RenderMode, RewardTerms, Step,
};
use crate::error::{EnvError, Result};
use crate::observation::{self, NoiseGroup};
use crate::spaces::BoxSpace;
use fairgrasp_sim::SimError;
use fairgrasp_sim::pick::{GraspStatus, SuccessRule, SuccessTracker};
use fairgrasp_sim::rapier3d::na::{Isometry3, Translation3, UnitQuaternion, Vector3};
use fairgrasp_sim::scene::{ObjectShape, PhysicalParams, Scene};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::VecDeque;
use std::ops::Range;

/// The Gymnasium id of the grasp task.
pub const ENV_ID: &str = "FaArmGrasp-v0";

/// State that lives for one episode.
#[derive(Clone, Debug)]
struct Episode {
    steps: u32,
    done: bool,
    tracker: SuccessTracker,
    previous_distance: f32,
    grasp_paid: bool,
    /// Previous applied action, normalised to [-1, 1].
    previous_action: Vec<f32>,
    /// Joint position targets (rad) the motors track.
    arm_target: Vec<f32>,
    /// Cartesian mode: the commanded TCP pose (world).
    tcp_target: Isometry3<f64>,
    /// Actions waiting to reach the robot (control latency).
    pending: VecDeque<Vec<f32>>,
    last_obs: Vec<f32>,
    params: EpisodeParams,
}

/// The grasp environment (see the crate documentation for the task).
pub struct GraspEnv {
    config: EnvConfig,
    scene: Scene,
    rng: ChaCha8Rng,
    observation_space: BoxSpace,
    action_space: BoxSpace,
    noise_groups: Vec<(Range<usize>, NoiseGroup)>,
    episode: Option<Episode>,
}

fn gaussian(rng: &mut impl Rng) -> f32 {
    let u1: f32 = rng.random::<f32>().max(1e-12);
    let u2: f32 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f32::consts::PI * u2).cos()
}

fn uniform(rng: &mut impl Rng, range: [f32; 2]) -> f32 {
    range[0] + (range[1] - range[0]) * rng.random::<f32>()
}

impl GraspEnv {
    /// Builds the environment. Call [`Env::reset`] before stepping.
    pub fn new(config: EnvConfig) -> Result<Self> {
        config.validate()?;
        let scene = Scene::new(config.scene.clone())?;
        if scene.arm_dof() != 6 {
            return Err(EnvError::config(
                "scene.arm.urdf",
                format!(
                    "the grasp task needs a six-joint arm, this one has {}",
                    scene.arm_dof()
                ),
            ));
        }
        let t = &config.task;
        let action_space = match t.action_mode {
            ActionMode::Joint => {
                let d = t.max_joint_delta;
                BoxSpace::new(
                    vec![-d, -d, -d, -d, -d, -d, -1.0],
                    vec![d, d, d, d, d, d, 1.0],
                )
            }
            ActionMode::Cartesian => {
                let (p, y) = (t.max_tcp_delta, t.max_yaw_delta);
                BoxSpace::new(vec![-p, -p, -p, -y, -1.0], vec![p, p, p, y, 1.0])
            }
        };
        let obs_dim = observation::observation_dim(t.observation, action_space.dim());
        Ok(Self {
            observation_space: BoxSpace::unbounded(obs_dim),
            noise_groups: observation::noise_groups(t.observation, action_space.dim()),
            action_space,
            rng: ChaCha8Rng::seed_from_u64(0),
            scene,
            config,
            episode: None,
        })
    }

    pub fn config(&self) -> &EnvConfig {
        &self.config
    }

    /// The simulation behind the environment (read-only: for scripted policies, rendering and
    /// tests).
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The joint position targets the motors currently track (rad).
    pub fn arm_target(&self) -> Option<&[f32]> {
        self.episode.as_ref().map(|e| e.arm_target.as_slice())
    }

    /// The physical parameters drawn for the current episode.
    pub fn episode_params(&self) -> Option<&EpisodeParams> {
        self.episode.as_ref().map(|e| &e.params)
    }

    /// Cartesian mode: the commanded TCP pose (world).
    pub fn tcp_target(&self) -> Option<Isometry3<f64>> {
        self.episode.as_ref().map(|e| e.tcp_target)
    }

    fn success_rule(&self) -> SuccessRule {
        SuccessRule {
            min_lift: self.config.task.success_min_lift as f64,
            max_offset: self.config.task.success_max_offset as f64,
            hold_steps: self.config.task.success_hold_steps,
        }
    }

    /// Arm parameters, object 0's `[edge, mass, friction]` (the configured ones when
    /// randomisation is off), whether those were drawn, joint jitter and latency.
    fn sample_params(&mut self) -> (PhysicalParams, [f32; 3], bool, Vec<f32>, u32) {
        let d = self.config.randomization.clone();
        let mut params = self.scene.nominal_params();
        let configured = &self.scene.config().objects[0];
        let edge = match configured.shape {
            ObjectShape::Box { size } => size[0],
            _ => 0.0,
        };
        let nominal_object = [edge, configured.mass, configured.friction];
        if !d.enabled {
            return (params, nominal_object, false, Vec::new(), 0);
        }
        let object_mass = uniform(&mut self.rng, d.object_mass);
        let object_friction = uniform(&mut self.rng, d.object_friction);
        let object_size = uniform(&mut self.rng, d.object_size);
        params.arm_damping = Some(
            (0..self.scene.arm_dof())
                .map(|_| uniform(&mut self.rng, d.joint_damping))
                .collect(),
        );
        params.gain_scale = uniform(&mut self.rng, d.actuator_gain_scale);
        let latency = self.rng.random_range(0..=d.max_latency_steps);
        let jitter = (0..self.scene.arm_dof())
            .map(|_| (self.rng.random::<f32>() * 2.0 - 1.0) * d.initial_joint_jitter)
            .collect();
        let object = [object_size, object_mass, object_friction];
        (params, object, true, jitter, latency)
    }

    fn add_noise(&mut self, obs: &mut [f32]) {
        if !self.config.randomization.enabled {
            return;
        }
        let noise = &self.config.randomization.observation_noise;
        for (range, group) in &self.noise_groups {
            let std = group.std(noise);
            if std > 0.0 {
                for v in &mut obs[range.clone()] {
                    *v += std * gaussian(&mut self.rng);
                }
            }
        }
    }

    fn observe(&mut self, previous_action: &[f32]) -> Vec<f32> {
        let mut obs = Vec::with_capacity(self.observation_space.dim());
        observation::observe(
            &self.scene,
            self.config.task.observation,
            previous_action,
            &mut obs,
        );
        self.add_noise(&mut obs);
        obs
    }

    fn no_op_action(&self) -> Vec<f32> {
        let mut a = vec![0.0; self.action_space.dim()];
        *a.last_mut().expect("action has a gripper entry") = 1.0;
        a
    }

    fn check_action(&self, action: &[f32]) -> Result<()> {
        let n = self.action_space.dim();
        if action.len() != n {
            let layout = match self.config.task.action_mode {
                ActionMode::Joint => "6 joint-angle deltas and a gripper command",
                ActionMode::Cartesian => "dx, dy, dz, dyaw and a gripper command",
            };
            return Err(EnvError::Action(format!(
                "expected {n} values ({layout}), got {}",
                action.len()
            )));
        }
        if let Some(i) = action.iter().position(|v| !v.is_finite()) {
            return Err(EnvError::Action(format!(
                "value {i} is {}; actions must be finite",
                action[i]
            )));
        }
        Ok(())
    }

    /// Turns an action into motor targets.
    fn apply(&mut self, action: &[f32], events: &mut Vec<EpisodeEvent>) -> Result<()> {
        let open = *action.last().expect("checked length") > 0.0;
        let mode = self.config.task.action_mode;
        let max_joint_delta = self.config.task.max_joint_delta;
        let limits = self.scene.arm_limits();
        let q = self.scene.arm_positions();
        let base = self.scene.base_pose();
        let episode = self.episode.as_mut().expect("checked by step");
        match mode {
            ActionMode::Joint => {
                for i in 0..6 {
                    // Targets accumulate (a zero action holds the pose instead of letting it sag),
                    // but never run more than three steps ahead of the measured angle.
                    let lead = 3.0 * max_joint_delta;
                    let t = (episode.arm_target[i] + action[i]).clamp(q[i] - lead, q[i] + lead);
                    episode.arm_target[i] = t.clamp(limits[i].0, limits[i].1);
                }
            }
            ActionMode::Cartesian => {
                let local_delta =
                    Vector3::new(action[0] as f64, action[1] as f64, action[2] as f64);
                let mut target = episode.tcp_target;
                target.translation.vector += base.rotation * local_delta;
                target.rotation =
                    UnitQuaternion::from_euler_angles(0.0, 0.0, action[3] as f64) * target.rotation;
                // Keep the commanded TCP inside a box around the placement area.
                let local = base.inverse() * target;
                let p = &self.config.scene.placement;
                let margin = 0.15;
                let top = self.scene.table_top() as f64 - base.translation.z;
                let clamped = Vector3::new(
                    local.translation.x.clamp(
                        (p.center[0] - p.size[0] / 2.0) as f64 - margin,
                        (p.center[0] + p.size[0] / 2.0) as f64 + margin,
                    ),
                    local.translation.y.clamp(
                        (p.center[1] - p.size[1] / 2.0) as f64 - margin,
                        (p.center[1] + p.size[1] / 2.0) as f64 + margin,
                    ),
                    local.translation.z.clamp(top + 0.015, top + 0.45),
                );
                let target =
                    base * Isometry3::from_parts(Translation3::from(clamped), local.rotation);
                match self.scene.solve_ik(&target, &episode.arm_target) {
                    Ok(q) => {
                        episode.arm_target = q;
                        episode.tcp_target = target;
                    }
                    Err(_) => events.push(EpisodeEvent::IkFailed),
                }
            }
        }
        let target = episode.arm_target.clone();
        self.scene.set_arm_targets(&target)?;
        self.scene.set_gripper_open(open)?;
        Ok(())
    }

    fn info(&self, status: &GraspStatus, episode: &Episode) -> Info {
        Info {
            success: episode.tracker.succeeded(),
            grasped: status.closed_on_object,
            ee_object_distance: status.offset as f32,
            lift: status.lift as f32,
            success_streak: episode.tracker.consecutive(),
            elapsed_steps: episode.steps,
            ..Info::default()
        }
    }

    fn reward(
        &self,
        status: &GraspStatus,
        episode: &mut Episode,
        success: bool,
        off_table: bool,
    ) -> RewardTerms {
        let r = &self.config.reward;
        let distance = status.offset as f32;
        let mut terms = RewardTerms::default();
        match r.kind {
            RewardKind::Sparse => {
                if success {
                    terms.success = r.success;
                }
            }
            RewardKind::Staged => {
                let third = 1.0 / 3.0;
                terms.reach = third * (1.0 - (4.0 * distance).tanh());
                if status.closed_on_object {
                    terms.grasp = third;
                    // Linear in the lift: a steady gradient from the table up (a tanh
                    // saturating at the goal gave too little pull for the first centimetres).
                    let goal = self.config.task.success_min_lift + 0.01;
                    terms.lift = third * (status.lift as f32 / goal).clamp(0.0, 1.0);
                }
                terms.time = -1.0;
                if off_table {
                    let remaining = self
                        .config
                        .task
                        .max_episode_steps
                        .saturating_sub(episode.steps) as f32;
                    terms.off_table = -remaining;
                }
                if success {
                    terms.success = r.success;
                }
            }
            RewardKind::Hybrid => {
                terms.approach = r.approach * (episode.previous_distance - distance);
                if distance < r.near_radius {
                    terms.near = r.near;
                }
                // One-time bonuses: paid at most once per episode, so dropping and regrasping
                // the cube earns nothing more.
                if status.closed_on_object && !episode.grasp_paid {
                    terms.grasp = r.grasp;
                    episode.grasp_paid = true;
                }
                if success {
                    terms.lift_hold = r.lift_hold;
                }
                terms.time = -r.time_penalty;
                if off_table {
                    terms.off_table = -r.off_table_penalty;
                }
            }
        }
        episode.previous_distance = distance;
        terms
    }

    fn render_text(&self) -> String {
        let s = &self.scene;
        let tcp = s.tcp_pose().translation.vector;
        let obj = s.object_state(0).pose.translation.vector;
        let steps = self.episode.as_ref().map(|e| e.steps).unwrap_or(0);
        format!(
            "{ENV_ID} step {steps}: q = [{}] rad, tcp = ({:.3}, {:.3}, {:.3}) m, object = ({:.3}, {:.3}, {:.3}) m, opening = {:.1} mm, pads touching = {:?}",
            s.arm_positions()
                .iter()
                .map(|v| format!("{v:.3}"))
                .collect::<Vec<_>>()
                .join(", "),
            tcp.x,
            tcp.y,
            tcp.z,
            obj.x,
            obj.y,
            obj.z,
            s.gripper_opening() * 1000.0,
            s.finger_contacts(0)
        )
    }

    /// The step that ends an episode whose physics produced non-finite numbers.
    fn non_finite_step(&mut self) -> Step {
        let episode = self.episode.as_mut().expect("checked by step");
        episode.done = true;
        Step {
            obs: episode.last_obs.clone(),
            reward: 0.0,
            terminated: false,
            truncated: true,
            info: Info {
                elapsed_steps: episode.steps,
                events: vec![EpisodeEvent::NonFiniteState],
                ..Info::default()
            },
        }
    }
}

impl Env for GraspEnv {
    fn metadata(&self) -> Metadata {
        Metadata {
            id: ENV_ID,
            render_modes: vec![RenderMode::Ansi],
            render_fps: 1.0 / self.scene.control_period(),
        }
    }

    fn observation_space(&self) -> &BoxSpace {
        &self.observation_space
    }

    fn action_space(&self) -> &BoxSpace {
        &self.action_space
    }

    fn render_mode(&self) -> Option<RenderMode> {
        self.config.task.render_mode
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info)> {
        if let Some(seed) = seed {
            self.rng = ChaCha8Rng::seed_from_u64(seed);
        }
        let (params, object, drawn, jitter, latency) = self.sample_params();
        self.scene.restore_home(&params, &jitter)?;
        if drawn {
            let [size, mass, friction] = object;
            let cube = ObjectShape::Box { size: [size; 3] };
            self.scene.set_object_params(0, &cube, mass, friction)?;
        }
        self.scene.place_objects_at_random(&mut self.rng)?;
        let tcp = self.scene.tcp_pose();
        let yaw = tcp.rotation.euler_angles().2;
        let tcp_target = self.scene.top_down_pose(tcp.translation.vector, yaw);
        let no_op = self.no_op_action();
        let previous_action = vec![0.0; self.action_space.dim()];
        let status = GraspStatus::of(&self.scene, 0);
        let episode_params = EpisodeParams {
            object_size: object[0],
            object_mass: object[1],
            object_friction: object[2],
            arm_damping: params.arm_damping.clone().unwrap_or_default(),
            gain_scale: params.gain_scale,
            latency_steps: latency,
        };
        let obs = self.observe(&previous_action);
        let episode = Episode {
            steps: 0,
            done: false,
            tracker: SuccessTracker::new(self.success_rule()),
            previous_distance: status.offset as f32,
            grasp_paid: false,
            previous_action,
            arm_target: self.scene.arm_targets(),
            tcp_target,
            pending: std::iter::repeat_n(no_op, latency as usize).collect(),
            last_obs: obs.clone(),
            params: episode_params.clone(),
        };
        let mut info = self.info(&status, &episode);
        info.episode_params = Some(episode_params);
        self.episode = Some(episode);
        Ok((obs, info))
    }

    fn step(&mut self, action: &[f32]) -> Result<Step> {
        match &self.episode {
            None => return Err(EnvError::Usage("call reset() before step()".into())),
            Some(e) if e.done => {
                return Err(EnvError::Usage(
                    "the episode has ended; call reset() before stepping again".into(),
                ));
            }
            Some(_) => {}
        }
        self.check_action(action)?;
        let mut clipped = action.to_vec();
        self.action_space.clip(&mut clipped);

        // Control latency: the action applied now was chosen `latency` steps ago.
        let applied = {
            let episode = self.episode.as_mut().expect("checked");
            episode.pending.push_back(clipped);
            episode.pending.pop_front().expect("just pushed")
        };
        let mut events = Vec::new();
        self.apply(&applied, &mut events)?;
        match self.scene.step_control() {
            Ok(()) => {}
            Err(SimError::NonFinite(_)) => return Ok(self.non_finite_step()),
            Err(e) => return Err(e.into()),
        }

        let normalised: Vec<f32> = applied
            .iter()
            .zip(&self.action_space.high)
            .map(|(a, h)| a / h)
            .collect();
        let obs = self.observe(&normalised);
        if obs.iter().any(|v| !v.is_finite()) {
            return Ok(self.non_finite_step());
        }
        let status = GraspStatus::of(&self.scene, 0);
        let off_table = self.scene.object_off_table(0);
        let mut episode = self.episode.take().expect("checked");
        episode.steps += 1;
        let success = episode.tracker.update(&status);
        let terms = self.reward(&status, &mut episode, success, off_table);
        let terminated = success || off_table;
        let truncated = !terminated && episode.steps >= self.config.task.max_episode_steps;
        episode.done = terminated || truncated;
        episode.previous_action = normalised;
        episode.last_obs.clone_from(&obs);
        if off_table {
            events.push(EpisodeEvent::ObjectOffTable);
        }
        let mut info = self.info(&status, &episode);
        info.reward_terms = terms;
        info.events = events;
        self.episode = Some(episode);
        Ok(Step {
            obs,
            reward: terms.total(),
            terminated,
            truncated,
            info,
        })
    }

    fn render(&mut self) -> Result<Option<Frame>> {
        Ok(self
            .config
            .task
            .render_mode
            .map(|RenderMode::Ansi| Frame::Text(self.render_text())))
    }

    fn close(&mut self) {
        self.episode = None;
    }
}

/// Whether a preset/mode pair is valid (all are); listed for checkers and docs.
pub fn all_variants() -> Vec<(ObservationPreset, ActionMode, RewardKind)> {
    let mut out = Vec::new();
    for obs in [ObservationPreset::Seed23, ObservationPreset::Rich] {
        for mode in [ActionMode::Joint, ActionMode::Cartesian] {
            for reward in [RewardKind::Sparse, RewardKind::Hybrid, RewardKind::Staged] {
                out.push((obs, mode, reward));
            }
        }
    }
    out
}
