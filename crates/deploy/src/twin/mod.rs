//! A digital twin of the FAIRINO controller, backed by the simulator: the controller's XML-RPC
//! methods (127.0.0.1:20003, path `/RPC2`) and its CNDE state stream (127.0.0.1:20005), so the
//! deploy loop — or the vendor's own Python SDK, unchanged — can rehearse everything without a
//! robot.
//!
//! - [`controller`]: the controller's behaviour (enable, mode, MoveJ, servo sessions, gripper,
//!   faults, e-stop, safety stop, error codes) as a state machine; see its documentation for
//!   every rule and code;
//! - [`world`]: the task's scene stepped in real time on its own thread, and the task's judge
//!   of each episode;
//! - [`service`]: the XML-RPC methods, the vendor's and the twin's own (`Twin…`);
//! - [`servo_udp`]: the real-time servo commands on UDP (127.0.0.1:20007), the SDK's
//!   `cmdType = 1`;
//! - [`faults`]: what can be injected, and how;
//! - [`pose_feed`]: the object's pose as the user's perception would publish it;
//! - [`call_log`]: every call received.
//!
//! Joint angles on the wire are the simulator's, in degrees (identity calibration). The TCP is
//! the gripper's centre point, in mm and degrees, in the arm's base frame.
//!
//! # The twin's own methods
//! - `TwinInfo()` → `[0, "fairgrasp-twin", env_id]`: tells a client it talks to a twin.
//! - `TwinReset(seed)` → `0`: a new episode: arm at home, gripper open, objects placed by the
//!   task from `seed`; any motion is aborted.
//! - `TwinEpisodeResult()` → `[0, success, max_lift_mm, steps, failed, grasped, episode]`
//!   (0/1 flags; `steps` are control steps judged; `failed`: an object left the table).
//! - `TwinTally()` → `[0, episodes, successes]`: episodes counted so far (an episode counts
//!   once it ends, by a reset, if anything was commanded to move in it).
//! - `TwinInjectFault(name, value)` → `0` (or `4` and a message in the log for a bad fault):
//!   see [`faults`].
//! - `TwinTracking()` → `[0, delay_ms, tau_ms, …]`: the drives' tracking in force, j1 to j6
//!   (see [`faults`]).

pub mod call_log;
pub mod camera_feed;
pub mod controller;
pub mod evaluation;
pub mod faults;
pub mod gripper;
pub mod motion;
mod periodic_server;
pub mod pose_feed;
pub mod service;
pub mod servo_udp;
mod sim_loop;
pub mod simulated;
pub mod world;

#[cfg(test)]
mod controller_tests;

use crate::error::{DeployError, Result};
use crate::fairino::cnde::{CndeControl, CndeServer, FrameFate, FrameFates, StateSource};
use crate::fairino::xmlrpc::XmlRpcServer;
use crate::pose_source::PoseMessage;
use crate::robot::RobotState;
use call_log::{CallLog, CallRecord};
use camera_feed::{CameraFeed, FramesFn, TwinCamera};
use controller::{Controller, ControllerConfig, StartState, pose_to_wire};
use fairgrasp_env::random::standard_normal_f64;
use fairgrasp_sim::kinematics::SerialChain;
use fairgrasp_sim::rapier3d::na::Isometry3;
use faults::{FaultCommand, FaultSettings};
use pose_feed::PoseFeed;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use servo_udp::ServoPort;
use std::collections::VecDeque;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
pub use world::EpisodeResult;

pub use crate::runner::TWIN_NAME;

/// How a twin is set up.
#[derive(Clone, Debug)]
pub struct TwinConfig {
    /// The arm task staged (its scene and its success rule).
    pub env_id: String,
    /// The environment's configuration table (a model's settings, `--set` overrides).
    pub env_config: toml::Table,
    /// Address every server listens on: loopback unless told otherwise.
    pub bind: IpAddr,
    /// Port 0: any free port (see the handle for the one taken).
    pub rpc_port: u16,
    /// The CNDE state stream's port (TCP, 20005 on the controller); 0: any free port.
    pub cnde_port: u16,
    /// The real-time servo port (UDP, 20007 on the controller); `None`: not served.
    pub servo_udp_port: Option<u16>,
    /// `None`: no object-pose feed over TCP.
    pub pose_port: Option<u16>,
    /// Where to send the pose feed as UDP datagrams too.
    pub pose_udp: Option<SocketAddr>,
    /// Time between two messages of the pose feed.
    pub pose_period: Duration,
    /// The camera feed's TCP port, served when the staged environment observes camera images
    /// (`[camera]`); `None`: not served.
    pub camera_port: Option<u16>,
    /// Time between two frames of the camera feed.
    pub camera_period: Duration,
    /// Seed of the first episode's placement and of the injected noise.
    pub seed: u64,
    /// How the controller is found at power-on.
    pub start: StartState,
    /// Faults in force from the start.
    pub faults: Vec<FaultCommand>,
    /// Also write every call as a JSON line here.
    pub log: Option<PathBuf>,
}

impl Default for TwinConfig {
    /// The grasp task on the controller's own ports, on loopback.
    fn default() -> Self {
        Self {
            env_id: fairgrasp_env::ENV_ID.to_string(),
            env_config: toml::Table::new(),
            bind: IpAddr::V4(Ipv4Addr::LOCALHOST),
            rpc_port: 20003,
            cnde_port: 20005,
            servo_udp_port: Some(crate::fairino::udp::DEFAULT_PORT),
            pose_port: Some(20100),
            pose_udp: None,
            pose_period: Duration::from_millis(33),
            camera_port: Some(20101),
            camera_period: Duration::from_millis(33),
            seed: 0,
            start: StartState::default(),
            faults: Vec::new(),
            log: None,
        }
    }
}

impl TwinConfig {
    /// The defaults on free ports (for tests and for running several twins).
    pub fn ephemeral() -> Self {
        Self {
            rpc_port: 0,
            cnde_port: 0,
            servo_udp_port: Some(0),
            pose_port: Some(0),
            camera_port: Some(0),
            ..Self::default()
        }
    }
}

/// The episodes judged so far.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Tally {
    /// Episodes judged.
    pub episodes: u32,
    /// Of those, the successes.
    pub successes: u32,
    /// Every episode counted, oldest first.
    pub results: Vec<EpisodeResult>,
}

/// States kept for the stream-latency fault (s).
const HISTORY_SECONDS: f64 = 1.2;

/// What every thread of the twin shares.
pub(crate) struct Shared {
    clock: Instant,
    pub(crate) controller: Mutex<Controller>,
    /// Notified after every physics step (used with `controller`).
    pub(crate) ticked: Condvar,
    /// Locked before `controller` when both are needed.
    pub(crate) world: Mutex<World>,
    pub(crate) faults: Mutex<FaultSettings>,
    rng: Mutex<ChaCha8Rng>,
    /// Draws of reply latencies and of the stream's frame fates, each its own stream so one
    /// does not shift the other.
    latency_rng: Mutex<ChaCha8Rng>,
    frame_rng: Mutex<ChaCha8Rng>,
    chain: SerialChain,
    history: Mutex<VecDeque<(f64, RobotState)>>,
    object: Mutex<Option<(f64, Isometry3<f64>)>>,
    pub(crate) calls: CallLog,
    tally: Mutex<(Tally, u64)>,
    pub(crate) cnde: Arc<CndeControl>,
    pub(crate) shutdown: AtomicBool,
    pub(crate) overruns: AtomicU64,
    /// Datagrams on the servo port that were not a servo command.
    pub(crate) udp_rejected: AtomicU64,
    pub(crate) env_id: String,
    pub(crate) controller_ip: String,
}

use world::World;

impl Shared {
    /// Twin time: seconds since it started.
    pub(crate) fn now(&self) -> f64 {
        self.clock.elapsed().as_secs_f64()
    }

    fn record_state(&self, t: f64, state: RobotState, object: Option<Isometry3<f64>>) {
        let mut history = self.history.lock().expect("history lock");
        while history
            .front()
            .is_some_and(|(t0, _)| t - t0 > HISTORY_SECONDS)
        {
            history.pop_front();
        }
        history.push_back((t, state));
        drop(history);
        *self.object.lock().expect("object lock") = object.map(|o| (t, o));
    }

    /// The state as reported `delay` seconds late, with the encoder noise in force.
    pub(crate) fn reported_state(&self, delay: f64) -> RobotState {
        let noise = self.faults.lock().expect("faults lock").joint_noise_deg;
        let mut state = {
            let history = self.history.lock().expect("history lock");
            let target = self.now() - delay;
            let found = if delay > 0.0 {
                history.iter().rev().find(|(t, _)| *t <= target)
            } else {
                None
            };
            found
                .or(history.back())
                .map(|(_, s)| s.clone())
                .unwrap_or_default()
        };
        if noise > 0.0 {
            let mut rng = self.rng.lock().expect("rng lock");
            for q in &mut state.joints_deg {
                *q += noise * standard_normal_f64(&mut *rng);
            }
            let rad: Vec<f64> = state.joints_deg.iter().map(|v| v.to_radians()).collect();
            state.tcp = pose_to_wire(&self.chain.forward(&rad));
        }
        state
    }

    /// What the CNDE stream sends now.
    fn stream_state(&self) -> RobotState {
        let delay = self.faults.lock().expect("faults lock").stream_latency_ms / 1000.0;
        self.reported_state(delay)
    }

    /// The object-pose message of now, with the pose noise in force.
    fn object_message(&self) -> Option<PoseMessage> {
        let (t, pose) = (*self.object.lock().expect("object lock"))?;
        let noise_mm = self.faults.lock().expect("faults lock").pose_noise_mm;
        let mut position = [pose.translation.x, pose.translation.y, pose.translation.z];
        if noise_mm > 0.0 {
            let mut rng = self.rng.lock().expect("rng lock");
            for p in &mut position {
                *p += noise_mm / 1000.0 * standard_normal_f64(&mut *rng);
            }
        }
        let q = pose.rotation.quaternion();
        Some(PoseMessage {
            position,
            orientation_xyzw: [q.i, q.j, q.k, q.w],
            stamp: Some(t),
        })
    }

    /// Injects one fault. (The fault settings are never locked while the controller is.)
    pub(crate) fn apply(&self, fault: &FaultCommand) {
        let now = self.now();
        let settings = || self.faults.lock().expect("faults lock");
        match fault {
            FaultCommand::LatencyMs(v) => settings().latency_ms = *v,
            FaultCommand::StreamLatencyMs(v) => settings().stream_latency_ms = *v,
            FaultCommand::JointNoiseDeg(v) => settings().joint_noise_deg = *v,
            FaultCommand::PoseNoiseMm(v) => settings().pose_noise_mm = *v,
            FaultCommand::Slow(s) => settings().slow = s.clone(),
            FaultCommand::Stall(on) => {
                settings().stalled = *on;
                self.cnde.set_stalled(*on);
            }
            FaultCommand::ResetStream => self.cnde.reset_all(),
            FaultCommand::Error { main, sub, fatal } => {
                self.controller().set_fault(now, *main, *sub, !fatal);
            }
            FaultCommand::Estop(on) => self.controller().set_estop(now, *on),
            FaultCommand::SafetyStop(s) => self.controller().set_safety_stop(now, *s),
            FaultCommand::LatencyJitterMs(v) => settings().latency_jitter_ms = *v,
            FaultCommand::LatencyOutliers(o) => settings().latency_outliers = *o,
            FaultCommand::DropFrames(p) => settings().drop_frames = *p,
            FaultCommand::LateFrames(o) => settings().late_frames = *o,
            FaultCommand::Tracking(m) => self.controller().set_tracking(*m),
            FaultCommand::FollowingErrorDeg(v) => self.controller().set_following_error(*v),
            FaultCommand::ServojSpeedTolerance(v) => {
                self.controller().set_servo_speed_tolerance(*v)
            }
            FaultCommand::BrakeDecelDegS2(v) => self.controller().set_brake_decel(*v),
            FaultCommand::CollisionLevelN(v) => self.controller().set_collision_level(*v),
            FaultCommand::Collision(on) => self.controller().set_collision(now, *on, 0),
            FaultCommand::Clear => {
                *settings() = FaultSettings::default();
                self.cnde.set_stalled(false);
                let mut c = self.controller();
                c.set_estop(now, false);
                c.set_safety_stop(now, [false; 2]);
                c.set_fault(now, 0, 0, true);
                c.restore_drive_defaults();
            }
        }
        tracing::info!("twin fault: {fault}");
    }

    /// One reply's latency (s), drawn from the faults in force.
    pub(crate) fn draw_latency(&self) -> f64 {
        let faults = self.faults.lock().expect("faults lock").clone();
        let mut rng = self.latency_rng.lock().expect("rng lock");
        faults.draw_latency_ms(&mut *rng) / 1000.0
    }

    /// What happens to the next CNDE frame due.
    fn frame_fate(&self) -> FrameFate {
        let faults = self.faults.lock().expect("faults lock").clone();
        if faults.drop_frames == 0.0 && faults.late_frames.is_none() {
            return FrameFate::Send;
        }
        let mut rng = self.frame_rng.lock().expect("rng lock");
        faults.draw_frame_fate(&mut *rng)
    }

    pub(crate) fn controller(&self) -> std::sync::MutexGuard<'_, Controller> {
        self.controller.lock().expect("controller lock")
    }

    /// Ends the current episode (counted if anything moved in it) and starts the next.
    /// Returns the episode that ended.
    pub(crate) fn reset_episode(&self, seed: u64) -> Result<EpisodeResult> {
        let mut world = self.world.lock().expect("world lock");
        let ended = world.episode().clone();
        world.start_episode(seed)?;
        let measured = world.measure();
        let now = self.now();
        let (state, commands) = {
            let mut c = self.controller();
            c.rehome(now, measured.joints_deg);
            c.observe(now, measured);
            (c.state(), c.motion_commands())
        };
        // Published at once: nobody should see the old cube after the reset returned.
        self.record_state(now, state, world.object_pose());
        let mut tally = self.tally.lock().expect("tally lock");
        let (t, commands_at_start) = &mut *tally;
        if commands > *commands_at_start {
            t.episodes += 1;
            t.successes += ended.success as u32;
            t.results.push(ended.clone());
        }
        *commands_at_start = commands;
        Ok(ended)
    }

    pub(crate) fn tally(&self) -> Tally {
        self.tally.lock().expect("tally lock").0.clone()
    }
}

/// A running twin; everything stops when it is dropped.
pub struct TwinHandle {
    shared: Arc<Shared>,
    rpc: XmlRpcServer,
    cnde: CndeServer,
    servo_udp: Option<ServoPort>,
    pose: Option<PoseFeed>,
    camera: Option<CameraFeed>,
    sim: Option<JoinHandle<()>>,
}

/// Starts twins.
pub struct Twin;

fn listen_error(what: &str, addr: SocketAddr, e: std::io::Error) -> DeployError {
    DeployError::Network {
        call: format!("listen ({what})"),
        addr: addr.to_string(),
        message: e.to_string(),
    }
}

impl Twin {
    /// Builds the world, starts the physics thread and the servers.
    pub fn spawn(config: TwinConfig) -> Result<TwinHandle> {
        let world = World::new(&config.env_id, &config.env_config, config.seed)?;
        let chain = world.chain().clone();
        let controller_config = ControllerConfig::fr5(&world.limits(), config.start.clone());
        let mut controller =
            Controller::new(controller_config, chain.clone(), world.home_deg(), 0.0);
        controller.observe(0.0, world.measure());
        let initial = controller.state();
        let object = world.object_pose();
        let shared = Arc::new(Shared {
            clock: Instant::now(),
            controller: Mutex::new(controller),
            ticked: Condvar::new(),
            world: Mutex::new(world),
            faults: Mutex::new(FaultSettings::default()),
            rng: Mutex::new(ChaCha8Rng::seed_from_u64(config.seed ^ 0x7717_7717)),
            latency_rng: Mutex::new(ChaCha8Rng::seed_from_u64(config.seed ^ 0x1a7e_0c1e)),
            frame_rng: Mutex::new(ChaCha8Rng::seed_from_u64(config.seed ^ 0xf4a3_e5ed)),
            chain,
            history: Mutex::new(VecDeque::new()),
            object: Mutex::new(None),
            calls: CallLog::new(config.log.as_deref())?,
            tally: Mutex::new((Tally::default(), 0)),
            cnde: CndeControl::new(),
            shutdown: AtomicBool::new(false),
            overruns: AtomicU64::new(0),
            udp_rejected: AtomicU64::new(0),
            env_id: config.env_id.clone(),
            controller_ip: config.bind.to_string(),
        });
        shared.record_state(0.0, initial, object);
        for fault in &config.faults {
            shared.apply(fault);
        }
        {
            // Weak: the stream's control is part of `shared`, a strong link would keep it alive.
            let weak = Arc::downgrade(&shared);
            let fates: FrameFates = Arc::new(move || {
                weak.upgrade()
                    .map_or(FrameFate::Send, |shared| shared.frame_fate())
            });
            shared.cnde.set_fates(Some(fates));
        }

        let rpc_addr = SocketAddr::new(config.bind, config.rpc_port);
        let rpc = XmlRpcServer::spawn(
            rpc_addr,
            Arc::new(service::TwinService::new(shared.clone())),
        )
        .map_err(|e| listen_error("XML-RPC", rpc_addr, e))?;
        let cnde_addr = SocketAddr::new(config.bind, config.cnde_port);
        let source: StateSource = {
            let shared = shared.clone();
            Arc::new(move || shared.stream_state())
        };
        let cnde = CndeServer::spawn(cnde_addr, source, shared.cnde.clone())
            .map_err(|e| listen_error("CNDE", cnde_addr, e))?;
        let servo_udp = match config.servo_udp_port {
            Some(port) => {
                let addr = SocketAddr::new(config.bind, port);
                Some(
                    ServoPort::spawn(addr, shared.clone())
                        .map_err(|e| listen_error("UDP servo port", addr, e))?,
                )
            }
            None => None,
        };
        let pose = match config.pose_port {
            Some(port) => {
                let addr = SocketAddr::new(config.bind, port);
                let source = {
                    let shared = shared.clone();
                    Arc::new(move || shared.object_message())
                };
                Some(
                    PoseFeed::spawn(addr, config.pose_udp, config.pose_period, source)
                        .map_err(|e| listen_error("object pose feed", addr, e))?,
                )
            }
            None => None,
        };
        let staged_camera = match config.camera_port {
            Some(_) => {
                let world = shared.world.lock().expect("world lock");
                TwinCamera::for_env(&config.env_config, world.scene())?
            }
            None => None,
        };
        let camera = match (config.camera_port, staged_camera) {
            (Some(port), Some(camera)) => {
                let addr = SocketAddr::new(config.bind, port);
                let camera = Mutex::new(camera);
                let source: FramesFn = {
                    let shared = shared.clone();
                    Arc::new(move || {
                        let world = shared.world.lock().expect("world lock");
                        let stamp = shared.now();
                        let mut camera = camera.lock().expect("camera lock");
                        match camera.frames(world.scene(), stamp) {
                            Ok(frames) => Some(frames),
                            Err(e) => {
                                tracing::error!("twin camera: {e}");
                                None
                            }
                        }
                    })
                };
                Some(
                    CameraFeed::spawn(addr, config.camera_period, source)
                        .map_err(|e| listen_error("camera feed", addr, e))?,
                )
            }
            _ => None,
        };
        let sim = {
            let shared = shared.clone();
            std::thread::Builder::new()
                .name("twin-physics".into())
                .spawn(move || sim_loop::run(shared))?
        };
        Ok(TwinHandle {
            shared,
            rpc,
            cnde,
            servo_udp,
            pose,
            camera,
            sim: Some(sim),
        })
    }
}

impl TwinHandle {
    /// Where the XML-RPC methods are served.
    pub fn rpc_addr(&self) -> SocketAddr {
        self.rpc.local_addr()
    }

    /// Where the CNDE stream is served.
    pub fn cnde_addr(&self) -> SocketAddr {
        self.cnde.local_addr()
    }

    /// Where the real-time servo commands are received (UDP).
    pub fn servo_udp_addr(&self) -> Option<SocketAddr> {
        self.servo_udp.as_ref().map(|p| p.local_addr())
    }

    /// Datagrams on the servo port that were not a servo command (each is in the call log).
    pub fn udp_rejected(&self) -> u64 {
        self.shared.udp_rejected.load(Ordering::Relaxed)
    }

    /// Where the object-pose feed is served over TCP.
    pub fn pose_addr(&self) -> Option<SocketAddr> {
        self.pose.as_ref().map(|p| p.local_addr())
    }

    /// Where the camera feed is served over TCP (when the staged environment has cameras).
    pub fn camera_addr(&self) -> Option<SocketAddr> {
        self.camera.as_ref().map(|c| c.local_addr())
    }

    /// The arm task staged.
    pub fn env_id(&self) -> &str {
        &self.shared.env_id
    }

    /// Twin time (s since start), as in the call log and the pose stamps.
    pub fn now(&self) -> f64 {
        self.shared.now()
    }

    /// Injects a fault, now.
    pub fn inject(&self, fault: FaultCommand) {
        self.shared.apply(&fault);
    }

    /// Injects a fault given as text (see [`faults`]).
    pub fn inject_text(&self, name: &str, value: &str) -> std::result::Result<(), String> {
        self.inject(FaultCommand::parse(name, value)?);
        Ok(())
    }

    /// How the drives follow their set points now (what a system identification should find).
    pub fn tracking(&self) -> faults::TrackingModel {
        self.shared.controller().tracking()
    }

    /// The lasting faults in force.
    pub fn faults(&self) -> FaultSettings {
        self.shared.faults.lock().expect("faults lock").clone()
    }

    /// The XML-RPC calls received (the newest [`call_log::MAX_KEPT`]).
    pub fn calls(&self) -> Vec<CallRecord> {
        self.shared.calls.calls()
    }

    /// Forgets the calls kept in memory (a call log file keeps its lines).
    pub fn clear_calls(&self) {
        self.shared.calls.clear();
    }

    /// The controller's true state now (no noise, no latency).
    pub fn state(&self) -> RobotState {
        self.shared.controller().state()
    }

    /// Runs `f` on the controller (for tests that look inside).
    pub fn with_controller<R>(&self, f: impl FnOnce(&mut Controller) -> R) -> R {
        f(&mut self.shared.controller())
    }

    /// Object 0's pose in the base frame, as the feed publishes it (noise included).
    pub fn object_pose(&self) -> Option<PoseMessage> {
        self.shared.object_message()
    }

    /// Ends the episode and starts the next from `seed` (as `TwinReset`); returns the one
    /// that ended.
    pub fn reset_episode(&self, seed: u64) -> Result<EpisodeResult> {
        self.shared.reset_episode(seed)
    }

    /// The current episode so far.
    pub fn episode(&self) -> EpisodeResult {
        self.shared
            .world
            .lock()
            .expect("world lock")
            .episode()
            .clone()
    }

    /// The episodes counted so far.
    pub fn tally(&self) -> Tally {
        self.shared.tally()
    }

    /// CNDE connections open now.
    pub fn cnde_connections(&self) -> usize {
        self.shared.cnde.live_connections()
    }

    /// Times the physics fell more than a quarter second behind real time.
    pub fn overruns(&self) -> u64 {
        self.shared.overruns.load(Ordering::Relaxed)
    }
}

impl Drop for TwinHandle {
    fn drop(&mut self) {
        self.shared.shutdown.store(true, Ordering::SeqCst);
        self.shared.ticked.notify_all();
        self.rpc.shutdown();
        self.cnde.shutdown();
        self.pose = None;
        self.camera = None;
        if let Some(port) = self.servo_udp.as_mut() {
            port.join();
        }
        if let Some(sim) = self.sim.take() {
            let _ = sim.join();
        }
    }
}
