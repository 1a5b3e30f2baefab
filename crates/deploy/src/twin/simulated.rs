//! The twin's controller and world in this process on a simulated clock: a [`RobotLink`], a
//! [`PoseSource`] and an [`EpisodeHost`] for the deployment loop, so that the deployment's own
//! code — its state estimation, safety filter and servo schedule — runs against the same
//! controller model as `fairgrasp twin`, at many times real time and independent of the host's
//! load. This is the deployment-matched evaluation (`fairgrasp eval --deployment`).
//!
//! Time moves only when the loop waits ([`RobotLink::sleep_until`]) or a call takes its reply
//! latency (drawn per call, half before the call acts and half after, as the twin's
//! `latency_ms` fault). The world steps at its physics rate under the controller's set points;
//! the state stream keeps a snapshot every stream period (the CNDE frame a real client reads),
//! with encoder noise, the pose feed one every feed period, and a camera policy's camera a
//! frame every camera period, visible a camera delay later.

use super::camera_feed::TwinCamera;
use super::controller::{Controller, ControllerConfig, StartState};
use super::faults::TrackingModel;
use super::world::World;
use crate::error::{DeployError, Result};
use crate::fairino::error_codes::codes;
use crate::fairino::error_codes::error_code_meaning;
use crate::frame_source::{FrameSource, ReceivedImages};
use crate::pose_source::{PoseMessage, PoseSource, ReceivedPose};
use crate::robot::{RobotCommand, RobotLink, RobotState, StampedState};
use crate::runner::EpisodeHost;
use fairgrasp_env::random::standard_normal_f64;
use fairgrasp_sim::rapier3d::na::Isometry3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// How the simulated controller behaves beyond the controller model.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatedSettings {
    /// Each call's reply latency (ms), drawn uniformly from this range.
    pub latency_ms: [f64; 2],
    /// Encoder noise on the streamed joint angles (deg, standard deviation).
    pub joint_noise_deg: f64,
    /// The state stream's period (ms): the CNDE frame period.
    pub stream_period_ms: f64,
    /// The object pose feed's period (ms).
    pub pose_period_ms: f64,
    /// The camera's frame period (ms), when the staged environment has cameras.
    pub camera_period_ms: f64,
    /// How long after its capture a frame reaches the loop (ms): exposure, readout, transfer.
    pub camera_delay_ms: f64,
    /// Seed of the first episode's placement (episode `i` uses `seed + i`) and of the noise.
    pub seed: u64,
}

impl Default for SimulatedSettings {
    /// As `fairgrasp twin --latency-ms 10 --joint-noise-deg 0.05`, with the latency drawn
    /// between 5 and 15 ms.
    fn default() -> Self {
        Self {
            latency_ms: [5.0, 15.0],
            joint_noise_deg: 0.05,
            stream_period_ms: 8.0,
            pose_period_ms: 1000.0 / 30.0,
            camera_period_ms: 1000.0 / 30.0,
            camera_delay_ms: 40.0,
            seed: 0,
        }
    }
}

impl SimulatedSettings {
    /// Checks every value; errors name the key.
    pub fn validate(&self) -> Result<()> {
        let [lo, hi] = self.latency_ms;
        if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo <= hi && hi <= 1000.0) {
            return Err(DeployError::config(
                "latency_ms",
                format!("must be [low, high] with 0 <= low <= high <= 1000, got {lo}, {hi}"),
            ));
        }
        for (key, v, max) in [
            ("joint_noise_deg", self.joint_noise_deg, 10.0),
            ("stream_period_ms", self.stream_period_ms, 1000.0),
            ("pose_period_ms", self.pose_period_ms, 1000.0),
            ("camera_period_ms", self.camera_period_ms, 1000.0),
            ("camera_delay_ms", self.camera_delay_ms, 1000.0),
        ] {
            let zero_ok = matches!(key, "joint_noise_deg" | "camera_delay_ms");
            if !(v.is_finite() && (0.0..=max).contains(&v)) || (!zero_ok && v == 0.0) {
                return Err(DeployError::config(
                    key,
                    format!("must be in (0, {max}], got {v}"),
                ));
            }
        }
        Ok(())
    }
}

/// A blocking MoveJ gives up after this long (s), as a real client's timeout would.
const MOVE_J_LIMIT: f64 = 60.0;
/// After a blocking MoveJ, two stream periods pass before its reply (as the twin does).
const STREAM_CATCH_UP: f64 = 0.016;

struct Inner {
    world: World,
    controller: Controller,
    settings: SimulatedSettings,
    rng: ChaCha8Rng,
    /// Simulated seconds since the start, and where that is on the loop's clock.
    t: f64,
    base: Instant,
    next_physics: f64,
    dt: f64,
    /// The last stream frame: its time, state and number.
    streamed: (f64, RobotState, u64),
    next_stream: f64,
    /// The last pose feed sample.
    pose: Option<(f64, Isometry3<f64>)>,
    next_pose: f64,
    /// The staged cameras, and their last frames with their capture times, oldest first.
    camera: Option<TwinCamera>,
    frames: VecDeque<(f64, Vec<u8>)>,
    next_frame: f64,
}

/// Frames kept: enough to cover a camera delay of several periods.
const FRAMES_KEPT: usize = 32;

impl Inner {
    fn instant(&self, t: f64) -> Instant {
        self.base + Duration::from_secs_f64(t)
    }

    /// Steps the world up to time `t`.
    fn advance_to(&mut self, t: f64) -> Result<()> {
        while self.next_physics <= t {
            let now = self.next_physics;
            let setpoint = self.controller.setpoint(now);
            self.world.step(&setpoint)?;
            self.controller.observe(now, self.world.measure());
            if now >= self.next_stream {
                self.publish_state(now);
                self.next_stream += self.settings.stream_period_ms / 1000.0;
            }
            if now >= self.next_pose {
                self.pose = self.world.object_pose().map(|p| (now, p));
                self.next_pose += self.settings.pose_period_ms / 1000.0;
            }
            if self.camera.is_some() && now >= self.next_frame {
                self.capture(now)?;
                self.next_frame += self.settings.camera_period_ms / 1000.0;
            }
            self.next_physics += self.dt;
        }
        self.t = self.t.max(t);
        Ok(())
    }

    /// Draws the cameras' frame of the world as it is now, stamped as captured at `stamp`.
    fn capture(&mut self, stamp: f64) -> Result<()> {
        if let Some(camera) = &mut self.camera {
            let frames = camera.frames(self.world.scene(), stamp)?;
            let bytes = frames.into_iter().flat_map(|(_, pixels)| pixels).collect();
            if self.frames.len() == FRAMES_KEPT {
                self.frames.pop_front();
            }
            self.frames.push_back((stamp, bytes));
        }
        Ok(())
    }

    fn publish_state(&mut self, now: f64) {
        let mut state = self.controller.state();
        if self.settings.joint_noise_deg > 0.0 {
            for q in &mut state.joints_deg {
                *q += self.settings.joint_noise_deg * standard_normal_f64(&mut self.rng);
            }
        }
        self.streamed = (now, state, self.streamed.2 + 1);
    }

    fn latency(&mut self) -> f64 {
        let [lo, hi] = self.settings.latency_ms;
        (lo + (hi - lo) * self.rng.random::<f64>()) / 1000.0
    }

    /// What a command does to the controller at the present time: its return code.
    fn apply(&mut self, command: &RobotCommand) -> Result<i32> {
        let now = self.t;
        let c = &mut self.controller;
        Ok(match command {
            RobotCommand::RobotEnable { enable } => c.enable(now, *enable),
            RobotCommand::Mode { mode } => c.set_mode(now, *mode as i64),
            RobotCommand::SetSpeed { percent } => c.set_speed(*percent as f64),
            RobotCommand::MoveJ {
                joints_deg,
                speed_percent,
                acc_percent,
            } => match c.move_j(now, *joints_deg, *speed_percent, *acc_percent, 100.0) {
                Err(code) => code,
                Ok(ticket) => {
                    let until = now + MOVE_J_LIMIT;
                    while self.controller.outcome(ticket).is_none() && self.t < until {
                        let next = self.t + self.dt;
                        self.advance_to(next)?;
                    }
                    let outcome = self.controller.outcome(ticket);
                    let next = self.t + STREAM_CATCH_UP;
                    self.advance_to(next)?;
                    outcome.unwrap_or(codes::WAIT_TIMEOUT)
                }
            },
            RobotCommand::ServoMoveStart => c.servo_start(),
            RobotCommand::ServoJ { joints_deg, cmd_t } => c.servo_j(now, *joints_deg, *cmd_t),
            RobotCommand::ServoMoveEnd => c.servo_end(),
            RobotCommand::StopMotion => c.stop_motion(now),
            RobotCommand::ResetAllError => c.reset_errors(),
            RobotCommand::ActGripper { index, activate } => {
                c.act_gripper(*index as i64, *activate as i64)
            }
            RobotCommand::MoveGripper {
                index,
                position_percent,
                speed_percent,
                force_percent,
                max_time_ms,
            } => {
                let percent = [*position_percent, *speed_percent, *force_percent].map(i64::from);
                match c.move_gripper(now, *index as i64, percent, *max_time_ms as i64) {
                    Ok(_) => codes::OK,
                    Err(code) => code,
                }
            }
        })
    }

    /// A new episode from `seed`: the world reset, the arm at rest at home, every motion
    /// aborted (as `TwinReset`); the stream and the feed show it at once.
    fn reset(&mut self, seed: u64) -> Result<()> {
        self.world.start_episode(seed)?;
        let measured = self.world.measure();
        let now = self.t;
        self.controller.rehome(now, measured.joints_deg);
        self.controller.observe(now, measured);
        self.publish_state(now);
        self.pose = self.world.object_pose().map(|p| (now, p));
        // The camera runs on through a reset: the placed scene is seen in a frame that has
        // just arrived (captured a delay ago), the next one a period later.
        self.frames.clear();
        let delay = self.settings.camera_delay_ms / 1000.0;
        self.capture(now - delay)?;
        self.next_frame = now + self.settings.camera_period_ms / 1000.0;
        Ok(())
    }
}

/// The simulated controller (see the [module](self)); clones share it.
#[derive(Clone)]
pub struct SimulatedController(Arc<Mutex<Inner>>);

impl SimulatedController {
    /// Stages `env_id` with its configuration table (a model's settings) behind the FR5's
    /// controller model, gripper not yet activated, the first episode placed from the seed.
    pub fn new(
        env_id: &str,
        env_config: &toml::Table,
        settings: SimulatedSettings,
    ) -> Result<Self> {
        settings.validate()?;
        let world = World::new(env_id, env_config, settings.seed)?;
        let camera = TwinCamera::for_env(env_config, world.scene())?;
        let controller = Controller::new(
            ControllerConfig::fr5(&world.limits(), StartState::default()),
            world.chain().clone(),
            world.home_deg(),
            0.0,
        );
        let dt = world.dt();
        let mut inner = Inner {
            world,
            controller,
            rng: ChaCha8Rng::seed_from_u64(settings.seed),
            settings,
            t: 0.0,
            base: Instant::now(),
            next_physics: 0.0,
            dt,
            streamed: (0.0, RobotState::default(), 0),
            next_stream: 0.0,
            pose: None,
            next_pose: 0.0,
            camera,
            frames: VecDeque::new(),
            next_frame: 0.0,
        };
        let seed = inner.settings.seed;
        inner.reset(seed)?;
        Ok(Self(Arc::new(Mutex::new(inner))))
    }

    fn inner(&self) -> MutexGuard<'_, Inner> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The object's pose feed.
    pub fn pose_source(&self) -> SimulatedPose {
        SimulatedPose(self.clone())
    }

    /// The staged camera's frames, for a camera policy (`None` when the staged environment has
    /// no cameras).
    pub fn frame_source(&self) -> Option<SimulatedFrames> {
        let inner = self.inner();
        let views = inner.camera.as_ref()?.space().views.len();
        Some(SimulatedFrames {
            controller: self.clone(),
            views,
        })
    }

    /// The episodes: episode `i` placed from `seed + i`, judged by the task's own rule on the
    /// true state.
    pub fn host(&self) -> SimulatedHost {
        let seed = self.inner().settings.seed;
        self.host_from(seed)
    }

    /// [`Self::host`] with episode `i` placed from `seed + i`.
    pub fn host_from(&self, seed: u64) -> SimulatedHost {
        SimulatedHost {
            controller: self.clone(),
            seed,
        }
    }

    /// Makes the drives follow their set points through `tracking` (the twin's `tracking`
    /// fault).
    pub fn set_tracking(&self, tracking: TrackingModel) {
        self.inner().controller.set_tracking(tracking);
    }

    /// The collision detection's level (N; `None`: off), as the twin's `collision_level_n`.
    pub fn set_collision_level(&self, newtons: Option<f64>) {
        self.inner().controller.set_collision_level(newtons);
    }

    /// A collision now, as the twin's `collision=1` fault: `collision_state` 1, `main_code`
    /// 201, the arm brakes, until `ResetAllError`.
    pub fn collide(&self) {
        let mut inner = self.inner();
        let now = inner.t;
        inner.controller.set_collision(now, true, 0);
    }

    /// Simulated seconds so far.
    pub fn elapsed(&self) -> f64 {
        self.inner().t
    }
}

impl RobotLink for SimulatedController {
    fn latest_state(&self) -> Result<StampedState> {
        let inner = self.inner();
        let (t, state, sequence) = inner.streamed.clone();
        Ok(StampedState {
            state,
            received_at: inner.instant(t),
            sequence,
        })
    }

    fn send(&mut self, command: &RobotCommand) -> Result<()> {
        let mut inner = self.inner();
        let latency = inner.latency();
        let acts_at = inner.t + latency / 2.0;
        inner.advance_to(acts_at)?;
        let code = inner.apply(command)?;
        let replies_at = inner.t + latency / 2.0;
        inner.advance_to(replies_at)?;
        if code == codes::OK {
            Ok(())
        } else {
            Err(DeployError::Controller {
                call: command.method().into(),
                code: code as i64,
                meaning: error_code_meaning(code as i64).into(),
            })
        }
    }

    fn now(&self) -> Instant {
        let inner = self.inner();
        inner.instant(inner.t)
    }

    fn sleep_until(&mut self, t: Instant) {
        let mut inner = self.inner();
        let target = t.saturating_duration_since(inner.base).as_secs_f64();
        if let Err(e) = inner.advance_to(target) {
            // The next state read fails the same way and stops the loop with the reason.
            tracing::error!("simulated controller: {e}");
        }
    }
}

/// The object's pose as the feed last published it.
pub struct SimulatedPose(SimulatedController);

impl PoseSource for SimulatedPose {
    fn latest(&mut self) -> Result<Option<ReceivedPose>> {
        let inner = self.0.inner();
        Ok(inner.pose.map(|(t, pose)| {
            let q = pose.rotation.quaternion();
            ReceivedPose {
                message: PoseMessage {
                    position: [pose.translation.x, pose.translation.y, pose.translation.z],
                    orientation_xyzw: [q.i, q.j, q.k, q.w],
                    stamp: Some(t),
                },
                received_at: inner.instant(t),
            }
        }))
    }
}

/// The newest frame that has reached the loop: captured at least the camera delay ago.
pub struct SimulatedFrames {
    controller: SimulatedController,
    views: usize,
}

impl FrameSource for SimulatedFrames {
    fn latest(&mut self) -> Result<Option<ReceivedImages>> {
        let inner = self.controller.inner();
        let delay = inner.settings.camera_delay_ms / 1000.0;
        let arrived = inner
            .frames
            .iter()
            .rev()
            .find(|(t, _)| t + delay <= inner.t);
        Ok(arrived.map(|(t, bytes)| ReceivedImages {
            bytes: bytes.clone(),
            received_at: inner.instant(t + delay),
            stamps: vec![*t; self.views],
        }))
    }
}

/// Places each episode and judges it by the task's rule on the true state.
pub struct SimulatedHost {
    controller: SimulatedController,
    seed: u64,
}

impl EpisodeHost for SimulatedHost {
    fn begin(&mut self, index: u32) -> Result<()> {
        self.controller.inner().reset(self.seed + index as u64)
    }

    fn outcome(&mut self) -> Result<Option<bool>> {
        Ok(Some(self.controller.inner().world.episode().success))
    }
}
