//! The shared base of every arm task (ManiSkill's `BaseEnv`): the simulated FR5 with its
//! gripper, the action mapping, control latency, domain randomisation, observation noise, time
//! limits and the Gymnasium contract. A task ([`Task`]) only places its objects, writes its
//! observation, evaluates its flags and pays its reward.
//!
//! - [`state`]: [`ArmState`], the plain state observations are computed from;
//! - [`control`]: [`ActionMapper`], action → joint targets;
//! - [`servo`]: [`JointRamp`], joint targets → capped set points (the deployment's motion);
//! - [`drives`]: [`ArmDrives`], set points → the joints' targets through the arm's drives;
//! - [`readings`]: [`StateEstimator`], controller readings → the policy's state (the
//!   deployment's observation);
//! - [`observation`]: [`ObsWriter`] and noise groups;
//! - [`task`]: [`Task`], what a task is to this base, and [`ArmEnvConfig`], its configuration;
//! - [`config`]: the shared configuration sections (randomisation, observation noise).

pub mod camera;
pub mod config;
pub mod control;
pub mod drives;
pub mod erased;
pub mod gripper;
pub mod observation;
pub mod readings;
pub mod servo;
pub mod shapes;
pub mod state;
pub mod task;

pub use camera::{CameraObsConfig, Cameras, ObsMode, SceneCameraConfig, WristCameraConfig};
pub use config::{ObservationNoise, RandomizationConfig, ShapeKind, ShapesConfig};
pub use control::{ActionMapper, ActionMode, Command, ControlConfig, MappingEvent};
pub use drives::{ArmDrives, DrivesConfig};
pub use erased::{ArmTaskEnv, ArmWorld};
pub use gripper::{GripperConfig, GripperDrive};
pub use observation::{NoiseGroup, ObsWriter};
pub use readings::{ControllerReading, EstimatorFacts, ReadingsConfig, StateEstimator};
pub use servo::{JointRamp, ServoConfig};
pub use state::{ArmState, ObjectReading};
pub use task::{
    ArmEnvConfig, Evaluation, RewardSettings, SuccessJudge, Task, TaskFlags, TaskSettings,
};

use crate::core::{Env, EpisodeEvent, Frame, Info, Metadata, NamedValues, RenderMode, Step};
use crate::error::{EnvError, Result};
use crate::random::uniform;
use crate::spaces::{BoxSpace, ImageSpace};
use fairgrasp_render::Renderer;
use fairgrasp_sim::SimError;
use fairgrasp_sim::kinematics::SerialChain;
use fairgrasp_sim::rapier3d::na::Isometry3;
use fairgrasp_sim::scene::{CollisionSensor, PhysicalParams, Scene};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::VecDeque;
use std::ops::Range;

/// State that lives for one episode.
#[derive(Clone, Debug)]
struct Episode {
    steps: u32,
    done: bool,
    /// In the controller's joint coordinates (the reported ones).
    command: Command,
    /// Actions waiting to reach the robot (control latency).
    pending: VecDeque<Vec<f32>>,
    /// The true state.
    state: ArmState,
    /// This episode's joint calibration errors (rad; empty when none are drawn).
    joint_offset: Vec<f32>,
    /// The state as the controller reports it, when it differs from the true one.
    reported: Option<ArmState>,
    last_obs: Vec<f32>,
    /// The servo set points (physical joints, rad), when `[control.servo]` is on.
    ramp: Option<JointRamp>,
    /// The gripper's set point, when `[control.gripper]` is on.
    gripper: Option<GripperDrive>,
    /// The arm's drives, when `[control.drives]` is on.
    drives: Option<ArmDrives>,
    /// What the controller's collision detection feels (`control.collision_force_limit`).
    collision_sensor: CollisionSensor,
    /// This episode's speed scale (`control.speed_scales`) and the physics substeps of one
    /// control step at it.
    speed_scale: f32,
    substeps: u32,
    /// With `[readings]`: the estimator and the state it built from this step's readings,
    /// which the policy and the action mapping see.
    estimator: Option<StateEstimator>,
    observed: Option<ArmState>,
    /// The last step's [`Info::privileged`] (`readings.privileged`).
    privileged: Vec<f32>,
}

impl Episode {
    /// The state as the controller reports it.
    fn reported_state(&self) -> &ArmState {
        self.reported.as_ref().unwrap_or(&self.state)
    }

    /// What the policy and the action mapping see.
    fn view(&self) -> &ArmState {
        self.observed
            .as_ref()
            .or(self.reported.as_ref())
            .unwrap_or(&self.state)
    }
}

/// An arm task as a Gymnasium-style environment.
///
/// **Joint calibration error** (`randomization.joint_offset`): each episode draws an offset
/// `e` per joint; the encoders report `q + e`, and the controller drives the *reported* angles
/// to its targets (the physical targets are the commanded ones minus `e`). The policy and the
/// action mapping see the reported joints and the TCP pose computed from them by the
/// kinematic model (as a controller computes it), while the object's pose, coming from
/// perception in the base frame, is true; rewards and success are judged on the true state.
/// Left out: the TCP velocity and the joint velocities stay the true ones (an offset of a
/// degree changes the Jacobian by a few percent), the home pose is the true one (the reported
/// home is off by `e`), and the offsets are constant over the episode (no drift, no backlash).
pub struct ArmEnv<T: Task> {
    config: ArmEnvConfig<T::Settings, T::Reward>,
    scene: Scene,
    task: T,
    mapper: ActionMapper,
    /// The robot description's damping of each arm joint (N·m·s/rad).
    nominal_damping: Vec<f32>,
    rng: ChaCha8Rng,
    observation_space: BoxSpace,
    /// The task's observation (the privileged state's), which a pixel mode does not show the
    /// policy; the observation space in [`ObsMode::State`].
    task_space: BoxSpace,
    /// The cameras of a pixel mode (`[camera]`).
    cameras: Option<Cameras>,
    action_space: BoxSpace,
    noise_groups: Vec<(Range<usize>, NoiseGroup)>,
    episode: Option<Episode>,
    /// Built at the first image render, so that environments that never render pay nothing.
    renderer: Option<Renderer>,
    /// What the state estimator knows beyond the readings (`[readings]`): the chain, the table,
    /// the gripper's stroke and this episode's object.
    facts: EstimatorFacts,
}

/// The controller's view of `state` under joint offsets `offset`: reported joints and the TCP
/// pose the kinematic model gives for them. `None` when there are no offsets.
fn reported(mapper: &ActionMapper, state: &ArmState, offset: &[f32]) -> Option<ArmState> {
    if offset.is_empty() {
        return None;
    }
    let mut reported = state.clone();
    for (q, e) in reported.q.iter_mut().zip(offset) {
        *q += e;
    }
    reported.tcp = mapper.forward(&reported.q);
    Some(reported)
}

/// The task's observation of `state` (in a pixel mode the arm's own readings instead), then
/// the speed scale when the policy observes it.
fn write_observation<T: Task>(
    task: &T,
    mode: ObsMode,
    observe_speed_scale: bool,
    state: &ArmState,
    previous_action: &[f32],
    speed_scale: f32,
    out: &mut ObsWriter,
) {
    match mode.has_images() {
        true => observation::arm_observation(state, previous_action, out),
        false => task.observe(state, previous_action, out),
    }
    if observe_speed_scale {
        out.push1(NoiseGroup::None, speed_scale);
    }
}

impl<T: Task> ArmEnv<T> {
    /// Builds the environment. Call [`Env::reset`] before stepping.
    pub fn new(config: ArmEnvConfig<T::Settings, T::Reward>) -> Result<Self> {
        config.validate()?;
        let mut scene_config = config.scene.clone();
        T::configure_scene(&config, &mut scene_config)?;
        let scene = Scene::new(scene_config)?;
        let chain = SerialChain::new(&scene.robot().model, "tcp")?;
        let mapper = ActionMapper::new(config.control.clone(), chain.clone(), scene.arm_limits())?;
        let task = T::new(&config, &scene)?;
        let action_space = mapper.action_space();
        let robot = scene.robot();
        let nominal_damping = scene
            .arm_joint_names()
            .iter()
            .map(|name| {
                let j = robot
                    .joint_index(name)
                    .expect("arm joints are robot joints");
                robot.model.joints[robot.joints[j].model_index].damping as f32
            })
            .collect();
        // Write one observation to learn its length and noise groups (and the task's own, which
        // a pixel mode's privileged state holds).
        let state = ArmState::from_scene(&scene);
        let facts = EstimatorFacts::new(chain.clone(), &state);
        let zeros = vec![0.0; action_space.dim()];
        let space = |mode| {
            let (mut obs, mut noise_groups) = (Vec::new(), Vec::new());
            write_observation(
                &task,
                mode,
                config.control.observe_speed_scale,
                &state,
                &zeros,
                1.0,
                &mut ObsWriter::recording(&mut obs, &mut noise_groups),
            );
            let mut high = vec![0.0; obs.len()];
            for (range, group) in &noise_groups {
                high[range.clone()].fill(group.bound());
            }
            let low = high.iter().map(|h| -h).collect();
            (BoxSpace::new(low, high), noise_groups)
        };
        let (observation_space, noise_groups) = space(config.camera.mode);
        let (task_space, _) = space(ObsMode::State);
        let cameras = Cameras::new(&config.camera, &scene)?;
        Ok(Self {
            observation_space,
            task_space,
            cameras,
            noise_groups,
            action_space,
            mapper,
            nominal_damping,
            task,
            rng: ChaCha8Rng::seed_from_u64(0),
            scene,
            config,
            episode: None,
            renderer: None,
            facts,
        })
    }

    /// The configuration it was built from; the scene as the task adjusted it is [`Self::scene`]'s.
    pub fn config(&self) -> &ArmEnvConfig<T::Settings, T::Reward> {
        &self.config
    }

    /// The simulation behind the environment (read-only: for scripted policies, rendering and
    /// tests).
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The task: its settings and per-episode state (goals, bins).
    pub fn task(&self) -> &T {
        &self.task
    }

    /// The renderer behind the image render modes, once [`Env::render`] has built it (for
    /// segmentation images and other cameras).
    pub fn renderer(&self) -> Option<&Renderer> {
        self.renderer.as_ref()
    }

    /// The action mapping (the same component the deployment loop uses).
    pub fn mapper(&self) -> &ActionMapper {
        &self.mapper
    }

    /// The true state at the last reset or step.
    pub fn state(&self) -> Option<&ArmState> {
        self.episode.as_ref().map(|e| &e.state)
    }

    /// The observation for a state read outside the simulator (the deployment loop) at speed
    /// scale `speed_scale`, with the previous action normalised as in [`Env::step`] (each value
    /// divided by its action-space bound). No observation noise is added.
    pub fn observation_of(
        &self,
        state: &ArmState,
        previous_action: &[f32],
        speed_scale: f32,
    ) -> Vec<f32> {
        let mut obs = Vec::with_capacity(self.observation_space.dim());
        self.write_observation(state, previous_action, speed_scale, &mut obs);
        self.observation_space.clip(&mut obs);
        obs
    }

    fn write_observation(
        &self,
        state: &ArmState,
        previous_action: &[f32],
        speed_scale: f32,
        obs: &mut Vec<f32>,
    ) {
        write_observation(
            &self.task,
            self.config.camera.mode,
            self.config.control.observe_speed_scale,
            state,
            previous_action,
            speed_scale,
            &mut ObsWriter::new(obs),
        );
    }

    /// Whether [`Info::privileged`] is reported: with `readings.privileged`, or in a pixel mode
    /// (whose policy never sees the object's pose).
    fn reports_privileged(&self) -> bool {
        self.config.readings.privileged || self.config.camera.mode.has_images()
    }

    /// The state as the controller reports it, which the last observation was computed from:
    /// [`Self::state`] unless joint offsets are drawn (see [`ArmEnv`]).
    pub fn reported_state(&self) -> Option<&ArmState> {
        self.episode.as_ref().map(Episode::reported_state)
    }

    /// The state the last observation was computed from: with `[readings]` the one estimated
    /// from synthesized controller readings, else [`Self::reported_state`].
    pub fn observed_state(&self) -> Option<&ArmState> {
        self.episode.as_ref().map(Episode::view)
    }

    /// What the state estimator knows beyond the readings, for this episode's object.
    pub fn estimator_facts(&self) -> &EstimatorFacts {
        &self.facts
    }

    /// This episode's joint calibration errors (rad; empty when none are drawn).
    pub fn joint_offset(&self) -> &[f32] {
        self.episode
            .as_ref()
            .map(|e| e.joint_offset.as_slice())
            .unwrap_or(&[])
    }

    /// What the arm is currently commanded to do (joint targets in the controller's reported
    /// coordinates).
    pub fn command(&self) -> Option<&Command> {
        self.episode.as_ref().map(|e| &e.command)
    }

    /// Draws this episode's physical parameters and object shapes and applies them; returns
    /// the latency and the `param/…` values for the reset info.
    fn randomize(&mut self) -> Result<(u32, NamedValues)> {
        let d = self.config.randomization.clone();
        let mut report = NamedValues::new();
        let dof = self.scene.arm_dof();
        let mut params = PhysicalParams::default();
        let mut jitter = Vec::new();
        let mut latency = 0;
        if d.enabled {
            let damping: Vec<f32> = (0..dof)
                .map(|j| match d.joint_damping_scale {
                    Some(scale) => self.nominal_damping[j] * uniform(&mut self.rng, scale),
                    None => uniform(&mut self.rng, d.joint_damping),
                })
                .collect();
            params.gain_scale = uniform(&mut self.rng, d.actuator_gain_scale);
            latency = self
                .rng
                .random_range(d.min_latency_steps..=d.max_latency_steps);
            jitter = (0..dof)
                .map(|_| (self.rng.random::<f32>() * 2.0 - 1.0) * d.initial_joint_jitter)
                .collect();
            for (j, v) in damping.iter().enumerate() {
                report.set(format!("param/joint_damping_{j}"), *v);
            }
            report.set("param/gain_scale", params.gain_scale);
            report.set("param/latency_steps", latency as f32);
            params.arm_damping = Some(damping);
        }
        self.scene.restore_home(&params, &jitter)?;
        for i in 0..self.scene.num_objects() {
            // As configured (before shape randomisation and scaling).
            let nominal = self.scene.config().objects[i].clone();
            let mut shape = if self.config.shapes.enabled {
                crate::arm::shapes::draw(&self.config.shapes, &mut self.rng)
            } else {
                nominal.shape
            };
            let (mut mass, mut friction) = (nominal.mass, nominal.friction);
            if d.enabled {
                mass = uniform(&mut self.rng, d.object_mass);
                friction = uniform(&mut self.rng, d.object_friction);
                shape = crate::arm::shapes::scaled(&shape, uniform(&mut self.rng, d.object_scale));
            }
            if d.enabled || self.config.shapes.enabled {
                report.set(format!("param/object{i}_mass"), mass);
                report.set(format!("param/object{i}_friction"), friction);
            }
            self.scene.set_object_params(i, &shape, mass, friction)?;
        }
        // Drawn only when set, so that configurations without it draw exactly as before.
        if let (true, Some(scale)) = (d.enabled, d.contact_stiffness_scale) {
            // Log-uniform: a scale spanning decades draws as often in each (15-30 Hz as
            // 150-300 Hz).
            let log_scale = uniform(&mut self.rng, scale.map(f32::ln)).exp();
            let hz = self.scene.config().physics.contact_frequency * log_scale;
            self.scene.set_contact_frequency(hz)?;
            report.set("param/contact_frequency", hz);
        }
        Ok((latency, report))
    }

    /// Draws this episode's joint calibration errors (none unless randomisation is on and
    /// `joint_offset` > 0, so other settings draw exactly as before) and reports them.
    fn draw_joint_offset(&mut self, report: &mut NamedValues) -> Vec<f32> {
        let d = &self.config.randomization;
        if !d.enabled || d.joint_offset <= 0.0 {
            return Vec::new();
        }
        let range = [-d.joint_offset, d.joint_offset];
        let offset: Vec<f32> = (0..self.scene.arm_dof())
            .map(|_| uniform(&mut self.rng, range))
            .collect();
        for (j, v) in offset.iter().enumerate() {
            report.set(format!("param/joint_offset_{j}"), *v);
        }
        offset
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
                    *v += std * crate::random::standard_normal(&mut self.rng);
                }
            }
        }
    }

    fn observe(&mut self, state: &ArmState, previous_action: &[f32], speed_scale: f32) -> Vec<f32> {
        let mut obs = Vec::with_capacity(self.observation_space.dim());
        self.write_observation(state, previous_action, speed_scale, &mut obs);
        self.add_noise(&mut obs);
        self.observation_space.clip(&mut obs);
        obs
    }

    /// A new estimator for the object now active and its first estimate, from `state` as the
    /// arm reports it (`reported`, where the readings differ from the truth).
    fn start_estimator(
        &mut self,
        state: &ArmState,
        reported: Option<&ArmState>,
        speed_scale: f32,
    ) -> (StateEstimator, ArmState) {
        self.facts.object = state.objects[0].clone();
        let mut estimator = StateEstimator::new();
        let view = reported.unwrap_or(state);
        let pose = state.objects[0].pose;
        let observed = self.estimate(&mut estimator, view, &pose, false, 0.0, speed_scale);
        (estimator, observed)
    }

    /// The state the policy sees with `[readings]`: the reported state read as a controller
    /// reports it (speeds in the policy's time at `speed_scale`), the object's pose from a feed
    /// of the configured rate (drawn age), through the estimator. `before` is object 0's true
    /// pose one control step earlier; `dt` is the control period in the policy's time (0 at
    /// reset).
    fn estimate(
        &mut self,
        estimator: &mut StateEstimator,
        view: &ArmState,
        before: &Isometry3<f64>,
        gripper_closing: bool,
        dt: f64,
        speed_scale: f32,
    ) -> ArmState {
        let qd: Vec<f32> = view.qd.iter().map(|v| v / speed_scale).collect();
        let reading = ControllerReading::synthesize(
            &view.q,
            &qd,
            view.gripper_opening,
            view.gripper_max_opening,
        );
        let max_age = self.config.readings.max_object_age();
        let now = view.objects[0].pose;
        let pose = if max_age > 0.0 && dt > 0.0 {
            // The feed runs in the simulator's time, where the step lasts dt / speed_scale.
            let age = max_age * self.rng.random::<f64>();
            readings::aged_pose(before, &now, age, dt / speed_scale as f64)
        } else {
            now
        };
        estimator.estimate(&self.facts, &reading, pose, gripper_closing, dt)
    }

    /// [`Info::privileged`]: the task's `state`-mode observation and the speed scale. With
    /// `readings.privileged`, of the true `state` (an asymmetric critic's input); otherwise, in
    /// a pixel mode, of the state as the arm reports it (`view`: the readings, when on), which
    /// is what a state policy of these settings observes and a distillation's teacher learnt
    /// from. Empty when neither.
    fn privileged(
        &self,
        state: &ArmState,
        view: &ArmState,
        previous_action: &[f32],
        speed_scale: f32,
    ) -> Vec<f32> {
        if !self.reports_privileged() {
            return Vec::new();
        }
        let state = if self.config.readings.privileged {
            state
        } else {
            view
        };
        let mut values = Vec::with_capacity(self.task_space.dim() + 1);
        write_observation(
            &self.task,
            ObsMode::State,
            self.config.control.observe_speed_scale,
            state,
            previous_action,
            speed_scale,
            &mut ObsWriter::new(&mut values),
        );
        self.task_space.clip(&mut values);
        values.push(speed_scale);
        values
    }

    /// Draws the cameras' images of the scene as it is now (nothing in [`ObsMode::State`]).
    fn capture(&mut self) -> Result<()> {
        match self.cameras.as_mut() {
            Some(cameras) => cameras.capture(&self.scene),
            None => Ok(()),
        }
    }

    /// Teleports the arm to its home joint vector at rest, its drives holding it there and the
    /// gripper commanded open; the actions in flight are dropped (no-ops replace them) and the
    /// servo's set points restart from home. [`Task::return_home`].
    fn send_arm_home(&mut self) -> Result<()> {
        let home = self.scene.config().arm.home.clone();
        self.scene.set_arm_positions(&home)?;
        self.scene.set_arm_targets(&home)?;
        let no_op = self.no_op_action();
        let episode = self.episode.as_mut().expect("an episode is running");
        match episode.gripper.as_mut() {
            None => self.scene.set_gripper_open(true)?,
            Some(g) => g.command(&self.scene, true),
        }
        for action in &mut episode.pending {
            action.clone_from(&no_op);
        }
        episode.ramp = (self.config.control.servo).ramp(&self.scene, episode.speed_scale);
        Ok(())
    }

    fn no_op_action(&self) -> Vec<f32> {
        let mut a = vec![0.0; self.action_space.dim()];
        *a.last_mut().expect("action has a gripper entry") = 1.0;
        a
    }

    fn check_action(&self, action: &[f32]) -> Result<()> {
        let n = self.action_space.dim();
        if action.len() != n {
            return Err(EnvError::Action(format!(
                "expected {n} values ({}), got {}",
                self.mapper.layout(),
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
                privileged: episode.privileged.clone(),
                ..Info::default()
            },
        }
    }

    fn render_text(&self) -> String {
        let state = ArmState::from_scene(&self.scene);
        let tcp = state.tcp.translation.vector;
        let steps = self.episode.as_ref().map(|e| e.steps).unwrap_or(0);
        let q: Vec<String> = state.q.iter().map(|v| format!("{v:.3}")).collect();
        format!(
            "{} step {steps}: q = [{}] rad, tcp = ({:.3}, {:.3}, {:.3}) m, opening = {:.1} mm. {}",
            T::ID,
            q.join(", "),
            tcp.x,
            tcp.y,
            tcp.z,
            state.gripper_opening * 1000.0,
            self.task.describe(&state)
        )
    }
}

impl<T: Task> Env for ArmEnv<T> {
    fn metadata(&self) -> Metadata {
        Metadata {
            id: T::ID,
            render_modes: vec![
                RenderMode::Ansi,
                RenderMode::RgbArray,
                RenderMode::DepthArray,
                RenderMode::SegmentationArray,
            ],
            render_fps: 1.0 / self.scene.control_period(),
        }
    }

    fn observation_space(&self) -> &BoxSpace {
        &self.observation_space
    }

    fn privileged_dim(&self) -> usize {
        match self.reports_privileged() {
            true => self.task_space.dim() + 1,
            false => 0,
        }
    }

    fn image_space(&self) -> Option<&ImageSpace> {
        self.cameras.as_ref().map(Cameras::space)
    }

    fn image(&self) -> Option<&[u8]> {
        self.episode.as_ref()?;
        self.cameras.as_ref().map(Cameras::image)
    }

    fn action_space(&self) -> &BoxSpace {
        &self.action_space
    }

    fn render_mode(&self) -> Option<RenderMode> {
        self.config.task.render_mode()
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info)> {
        if let Some(seed) = seed {
            self.rng = ChaCha8Rng::seed_from_u64(seed);
        }
        let (latency, mut params) = self.randomize()?;
        let speed_scale = match self.config.control.speed_scales.as_slice() {
            [one] => *one,
            scales => {
                let drawn = scales[self.rng.random_range(0..scales.len())];
                params.set("param/speed_scale", drawn);
                drawn
            }
        };
        let substeps =
            ((self.scene.config().physics.substeps as f32 / speed_scale).round() as u32).max(1);
        self.task
            .initialize_episode(&mut self.scene, &mut self.rng)?;
        // Drawn after the placement, so that offsets leave the episode's layout unchanged.
        let joint_offset = self.draw_joint_offset(&mut params);
        let state = ArmState::from_scene(&self.scene);
        let reported = reported(&self.mapper, &state, &joint_offset);
        let (mut estimator, mut observed) = (None, None);
        if self.config.readings.enabled {
            let (e, o) = self.start_estimator(&state, reported.as_ref(), speed_scale);
            (estimator, observed) = (Some(e), Some(o));
        }
        let view = (observed.as_ref()).or(reported.as_ref()).unwrap_or(&state);
        let mut targets = self.scene.arm_targets();
        for (t, e) in targets.iter_mut().zip(&joint_offset) {
            *t += e;
        }
        let command = self.mapper.hold(view, targets);
        let previous_action = vec![0.0; self.action_space.dim()];
        let obs = self.observe(view, &previous_action, speed_scale);
        let privileged = self.privileged(&state, view, &previous_action, speed_scale);
        let no_op = self.no_op_action();
        let ramp = self.config.control.servo.ramp(&self.scene, speed_scale);
        let gripper = (self.config.control.gripper).drive(&self.scene, speed_scale, &mut self.rng);
        let drives = match (self.config.control.drives).drives(&self.scene, &mut self.rng)? {
            Some((drives, scale)) => {
                let [lo, hi] = self.config.control.drives.scale;
                if lo < hi {
                    params.set("param/drive_scale", scale as f32);
                }
                Some(drives)
            }
            None => None,
        };
        self.episode = Some(Episode {
            steps: 0,
            done: false,
            command,
            pending: std::iter::repeat_n(no_op, latency as usize).collect(),
            state,
            joint_offset,
            reported,
            last_obs: obs.clone(),
            ramp,
            gripper,
            drives,
            collision_sensor: CollisionSensor::new(),
            speed_scale,
            substeps,
            estimator,
            observed,
            privileged: privileged.clone(),
        });
        if let Some(cameras) = self.cameras.as_mut() {
            // Drawn last, so that the episode's other draws are those of an unrandomised look.
            let seed = cameras.randomized().then(|| self.rng.random());
            cameras.start_episode(seed)?;
        }
        self.capture()?;
        Ok((
            obs,
            Info {
                extras: params,
                privileged,
                ..Info::default()
            },
        ))
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

        let mut events = Vec::new();
        let episode = self.episode.as_mut().expect("checked");
        // Control latency: the action applied now was chosen `latency` steps ago.
        episode.pending.push_back(clipped);
        let applied = episode.pending.pop_front().expect("just pushed");
        let view = (episode.observed.as_ref())
            .or(episode.reported.as_ref())
            .unwrap_or(&episode.state);
        if let Some(MappingEvent::IkFailed) =
            self.mapper.apply(view, &applied, &mut episode.command)
        {
            events.push(EpisodeEvent::IkFailed);
        }
        // The controller servoes the reported angles (q + e) to its targets.
        let physical: Vec<f32> = if episode.joint_offset.is_empty() {
            episode.command.arm_target.clone()
        } else {
            (episode.command.arm_target.iter())
                .zip(&episode.joint_offset)
                .map(|(t, e)| t - e)
                .collect()
        };
        match episode.gripper.as_mut() {
            None => self.scene.set_gripper_open(episode.command.gripper_open)?,
            Some(g) => g.command(&self.scene, episode.command.gripper_open),
        }
        // With `[readings]`, the readings may be this many substeps older than the step's end.
        let (substeps, speed_scale) = (episode.substeps, episode.speed_scale);
        let age = match &self.config.readings {
            r if r.enabled && r.state_age_ms[1] > 0.0 => {
                let ms = uniform(&mut self.rng, r.state_age_ms);
                let steps = (ms as f64 / 1000.0 / self.scene.dt() as f64).round() as u32;
                steps.min(substeps - 1)
            }
            _ => 0,
        };
        let mut early = None;
        let control = &self.config.control;
        let force_limit = control.collision_force_limit;
        let press_cost = (control.collision_penalty > 0.0)
            .then_some((control.collision_penalty, control.collision_penalty_force));
        let watch_force = force_limit.is_some() || press_cost.is_some();
        let mut peak_force: f32 = 0.0;
        let sensor = &mut episode.collision_sensor;
        let mut read_early = |scene: &Scene, done: u32| {
            if age > 0 && done == substeps - age {
                early = Some(ArmState::from_scene(scene));
            }
            if watch_force {
                sensor.read(scene);
                peak_force = peak_force.max(sensor.force());
            }
        };
        let mut gripper = episode.gripper.as_mut();
        let mut drive_gripper = |scene: &mut Scene| match gripper.as_mut() {
            Some(g) => g.drive(scene),
            None => Ok(()),
        };
        let stepped = match episode.ramp.as_mut() {
            None => self.scene.set_arm_targets(&physical).and_then(|()| {
                for done in 1..=substeps {
                    drive_gripper(&mut self.scene)?;
                    self.scene.step_physics()?;
                    read_early(&self.scene, done);
                }
                self.scene.check_finite()
            }),
            Some(ramp) => {
                let (scene, target) = (&mut self.scene, &physical);
                let drives = episode.drives.as_mut();
                servo::step_servoed(
                    scene,
                    ramp,
                    drives,
                    substeps,
                    target,
                    drive_gripper,
                    read_early,
                )
            }
        };
        match stepped {
            Ok(()) => {}
            Err(SimError::NonFinite(_)) => return Ok(self.non_finite_step()),
            Err(e) => return Err(e.into()),
        }

        let normalised: Vec<f32> = applied
            .iter()
            .zip(&self.action_space.high)
            .map(|(a, h)| a / h)
            .collect();
        let mut state = ArmState::from_scene(&self.scene);
        let mut reported = reported(&self.mapper, &state, &episode.joint_offset);
        let closing = !episode.command.gripper_open;
        let before = episode.state.objects.first().map(|o| o.pose);
        let mut estimator = episode.estimator.take();
        let mut observed = match (estimator.as_mut(), before) {
            (Some(e), Some(before)) => {
                let early = early.map(|s| {
                    let seen = self::reported(&self.mapper, &s, &episode.joint_offset);
                    seen.unwrap_or(s)
                });
                let view = (early.as_ref()).or(reported.as_ref()).unwrap_or(&state);
                let dt = self.scene.control_period() as f64;
                Some(self.estimate(e, view, &before, closing, dt, speed_scale))
            }
            _ => None,
        };
        // Judged before observing: the observation shows what the task now asks for (sorting's
        // next object once one is placed).
        let mut evaluation = self.task.evaluate(&self.scene, &state);
        if self.task.return_home() {
            self.send_arm_home()?;
            state = ArmState::from_scene(&self.scene);
            let episode = self.episode.as_ref().expect("checked");
            reported = self::reported(&self.mapper, &state, &episode.joint_offset);
            if let Some(e) = estimator.as_mut() {
                let (fresh, o) = self.start_estimator(&state, reported.as_ref(), speed_scale);
                (*e, observed) = (fresh, Some(o));
            }
            let view = (observed.as_ref()).or(reported.as_ref()).unwrap_or(&state);
            let mut targets = self.scene.arm_targets();
            let episode = self.episode.as_mut().expect("checked");
            for (t, e) in targets.iter_mut().zip(&episode.joint_offset) {
                *t += e;
            }
            episode.command = self.mapper.hold(view, targets);
            evaluation = self.task.evaluate(&self.scene, &state);
        }
        let view = (observed.as_ref()).or(reported.as_ref()).unwrap_or(&state);
        let obs = self.observe(view, &normalised, speed_scale);
        if obs.iter().any(|v| !v.is_finite()) {
            return Ok(self.non_finite_step());
        }
        let privileged = self.privileged(&state, view, &normalised, speed_scale);
        self.capture()?;
        let mut extras = evaluation.flags.named();
        if watch_force {
            extras.set("contact_force", peak_force);
        }
        if force_limit.is_some_and(|limit| peak_force > limit) {
            // The controller stops the arm: no success, whatever the task saw.
            evaluation.success = false;
            evaluation.failure = Some(EpisodeEvent::Collision);
        }
        let max_steps = self
            .task
            .episode_steps(self.config.task.max_episode_steps());
        let episode = self.episode.as_mut().expect("checked");
        episode.steps += 1;
        let steps_left = max_steps.saturating_sub(episode.steps);
        let mut reward_terms = self.task.reward(&evaluation, &state, steps_left);
        if let Some((penalty, force)) = press_cost {
            reward_terms.set("press", -penalty * (peak_force / force).min(4.0));
        }
        let terminated = evaluation.success || evaluation.failure.is_some();
        let truncated = !terminated && episode.steps >= max_steps;
        episode.done = terminated || truncated;
        episode.last_obs.clone_from(&obs);
        episode.state = state;
        episode.reported = reported;
        episode.estimator = estimator;
        episode.observed = observed;
        episode.privileged.clone_from(&privileged);
        events.extend(evaluation.failure);
        Ok(Step {
            obs,
            reward: reward_terms.total(),
            terminated,
            truncated,
            info: Info {
                success: evaluation.success,
                elapsed_steps: episode.steps,
                events,
                extras,
                reward_terms,
                privileged,
            },
        })
    }

    fn render(&mut self) -> Result<Option<Frame>> {
        let Some(mode) = self.config.task.render_mode() else {
            return Ok(None);
        };
        if mode == RenderMode::Ansi {
            return Ok(Some(Frame::Text(self.render_text())));
        }
        if self.renderer.is_none() {
            let renderer = Renderer::with_config(&self.scene, self.config.render.clone())?;
            self.renderer = Some(renderer);
        }
        let renderer = self.renderer.as_mut().expect("built above");
        renderer.render(&self.scene)?;
        let (width, height) = (renderer.width(), renderer.height());
        Ok(Some(match mode {
            RenderMode::DepthArray => Frame::Depth {
                width,
                height,
                data: renderer.depth().to_vec(),
            },
            RenderMode::SegmentationArray => Frame::Segmentation {
                width,
                height,
                data: renderer.segmentation().to_vec(),
            },
            _ => Frame::Rgb {
                width,
                height,
                data: renderer.rgb().to_vec(),
            },
        }))
    }

    fn close(&mut self) {
        self.episode = None;
    }
}
