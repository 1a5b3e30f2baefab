//! The deployment loop: the policy at its trained control rate, streaming ServoJ at the
//! controller's servo period through the safety layer.
//!
//! Each control step: read the newest state (the [`Watchdog`] judges it) and the object's
//! pose, build the policy's observation with the model's own code ([`ModelIo`]), act, map the
//! action to joint targets as in training, then stream set points towards them over the step's
//! servo periods, each from the [`SafetyFilter`] — the motion a model trained with
//! `[control.servo]` learnt in simulation. The speed scale slows all of it in time: the policy
//! steps at its control period over the scale, and the state it sees has its velocities
//! multiplied back, so at any scale the policy meets the motion it was trained on. Any fault — stale or failed state,
//! controller fault code, e-stop, safety stop, a failed call, a non-finite output, a workspace
//! exit, Ctrl-C — stops the arm (StopMotion, ServoMoveEnd) at once and ends the run with that
//! fault; nothing moves the arm afterwards ([`GuardedLink`]).

mod clock;
mod estimate;
mod guard;
mod hosts;
pub mod interrupt;
mod log;
mod model_io;

pub use clock::{MAX_CMD_T, ServoClock};
pub use estimate::ArmReader;
pub use guard::{GuardedLink, describe};
pub use hosts::{OperatorHost, TWIN_NAME, TwinHost};
pub use log::JsonLog;
pub use model_io::ModelIo;

use crate::calibration::Calibration;
use crate::error::{DeployError, Result};
use crate::fairino::fr5;
use crate::frame_source::FrameSource;
use crate::pose_source::PoseSource;
use crate::robot::{RobotCommand, RobotLink};
use crate::safety::{Fault, SafetyConfig, SafetyFilter, Watchdog};
use fairgrasp_rl::Policy;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// A set point within this of its target (deg) and slower than [`ARRIVED_DEG_S`] has arrived.
const ARRIVED_DEG: f64 = 0.05;
const ARRIVED_DEG_S: f64 = 0.5;
/// How fast a put-down moves (deg/s for the joint that moves farthest) at speed scale 1: a
/// fifth of the FR5's top joint speed, gentle enough to set an object down.
const PUT_DOWN_DEG_S: f64 = 36.0;
/// The longest a put-down waits at its goal for the set point to arrive at rest.
const SETTLE_LIMIT: Duration = Duration::from_secs(1);
/// The gripper counts as open from this position (%); its full stroke is 100.
const GRIPPER_OPEN_PERCENT: u8 = 90;
/// The longest the put-down waits for the gripper to open, streaming the same set point.
const GRIPPER_OPEN_LIMIT: Duration = Duration::from_secs(3);

/// How the loop runs.
#[derive(Clone, Debug)]
pub struct DeployOptions {
    /// Send commands (false: a dry run that prints them).
    pub live: bool,
    /// Episodes to run.
    pub episodes: u32,
    /// Control steps per episode (default: the model's episode length).
    pub max_steps: Option<u32>,
    /// The safety layer's limits.
    pub safety: SafetyConfig,
    /// The gripper's index on the controller (1–8).
    pub gripper_index: u8,
    /// How long to wait for the first object pose of an episode.
    pub pose_timeout: Duration,
    /// End an episode once the task's success rule has held for its hold steps, on the
    /// estimated state, as training's episodes ended (false: act until `max_steps`). The
    /// policy never learnt what to do after success: holding on, kinematic-drive policies
    /// drifted with the lifted cube to the workspace box's edge (2 of 3 twin runs stopped).
    pub end_at_success: bool,
    /// After the success rule held, keep the arm at its last target with the gripper closed
    /// for this many control steps before the episode ends: the loop judged success on its
    /// estimated state, a judge of the true state (the twin's, an operator's) on its own clock
    /// may count one step later.
    pub hold_after_success: u32,
    /// What becomes of the object once the success rule has held.
    pub after_success: AfterSuccess,
}

/// What the arm does with a grasped object when the episode ends at success.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AfterSuccess {
    /// Lower it back to where the gripper closed on it, open, and withdraw to the lifted pose.
    #[default]
    PutDown,
    /// Keep the gripper closed: the operator takes the object before the next episode, whose
    /// start opens the gripper at home.
    Hold,
}

impl Default for DeployOptions {
    fn default() -> Self {
        Self {
            live: false,
            episodes: 1,
            max_steps: None,
            safety: SafetyConfig::default(),
            gripper_index: 1,
            pose_timeout: Duration::from_secs(2),
            end_at_success: true,
            hold_after_success: 5,
            after_success: AfterSuccess::PutDown,
        }
    }
}

/// Prepares each episode and, where it can, judges it.
pub trait EpisodeHost {
    /// Gets episode `index` ready: the twin places a new object; at a real robot the operator
    /// is asked to.
    fn begin(&mut self, index: u32) -> Result<()>;
    /// Whether the grasp succeeded, when the host can tell (the twin, by the task's rule).
    fn outcome(&mut self) -> Result<Option<bool>>;
}

/// An episode's outcome.
#[derive(Clone, Debug, PartialEq)]
pub struct EpisodeReport {
    /// Control steps the policy acted.
    pub steps: u32,
    /// The loop saw the task's success rule hold for its hold steps and ended the episode.
    pub ended_at_success: bool,
    /// The host's judgement, if it gives one.
    pub success: Option<bool>,
    /// Control steps whose Cartesian target had no inverse kinematics.
    pub ik_failures: u32,
}

/// How a run ended.
#[derive(Debug)]
pub struct RunReport {
    /// The episodes that ended, in order (not one a fault stopped).
    pub episodes: Vec<EpisodeReport>,
    /// The fault that stopped the arm, if one did.
    pub fault: Option<Fault>,
    /// From the fault's detection to StopMotion and ServoMoveEnd both answered.
    pub stopped_in: Option<Duration>,
}

/// Everything the loop works with.
pub struct Deployment {
    link: GuardedLink,
    policy: Policy,
    io: ModelIo,
    calibration: Calibration,
    filter: SafetyFilter,
    watchdog: Watchdog,
    options: DeployOptions,
    interrupt: Arc<AtomicBool>,
    /// A camera policy's images ([`Self::set_camera`]).
    camera: Option<Box<dyn FrameSource>>,
    servo_ticks: u32,
    /// The servo period: the control period over the speed scale, divided evenly into
    /// `servo_ticks` periods of at most the configured one (6.67 ms at scale 1), so that a
    /// late send can cover two within the controller's longest cmdT.
    tick: Duration,
}

impl Deployment {
    /// Checks the model, calibration and safety settings against each other.
    pub fn new(
        link: Box<dyn RobotLink>,
        policy: Policy,
        calibration: Calibration,
        options: DeployOptions,
        log: JsonLog,
        interrupt: Arc<AtomicBool>,
    ) -> Result<Self> {
        calibration.validate()?;
        options.safety.validate()?;
        if options.episodes == 0 {
            return Err(DeployError::config("--episodes", "must be at least 1"));
        }
        let io = ModelIo::for_policy(&policy)?;
        let fk = io.arm_kinematics(&calibration);
        let servo = options.safety.servo_period_ms / 1000.0;
        let step = io.control_period / options.safety.speed_scale;
        let servo_ticks = ((step / servo - 1e-9).ceil() as u32).max(1);
        let tick = step / servo_ticks as f64;
        let mut safety = options.safety.clone();
        safety.servo_period_ms = tick * 1000.0;
        let filter = SafetyFilter::new(
            &safety,
            &calibration.soft_limits(),
            io.nominal.table_z * 1000.0,
            fk,
        )?;
        let watchdog = Watchdog::new(
            Duration::from_secs_f64(options.safety.state_deadline_ms / 1000.0),
            crate::fairino::error_codes::error_code_meaning,
        );
        Ok(Self {
            link: GuardedLink::new(link, options.live, log),
            policy,
            io,
            calibration,
            filter,
            watchdog,
            options,
            interrupt,
            camera: None,
            servo_ticks,
            tick: Duration::from_secs_f64(tick),
        })
    }

    /// Where a camera policy reads its images (a camera policy refuses to run without).
    pub fn set_camera(&mut self, frames: Box<dyn FrameSource>) {
        self.camera = Some(frames);
    }

    /// Servo periods per control step (the control period over the speed scale, over the
    /// configured servo period, rounded up).
    pub fn servo_ticks(&self) -> u32 {
        self.servo_ticks
    }

    /// The servo period: the control period over the speed scale, over [`Self::servo_ticks`].
    pub fn servo_period(&self) -> Duration {
        self.tick
    }

    /// Why the arm will not move as the policy learnt, if it will not
    /// ([`ModelIo::motion_mismatch`]).
    pub fn motion_mismatch(&self) -> Option<String> {
        self.io.motion_mismatch(&self.options.safety)
    }

    /// Why the policy will read the arm differently from how it learnt, if it will
    /// ([`ModelIo::observation_mismatch`]).
    pub fn observation_mismatch(&self) -> Option<String> {
        self.io.observation_mismatch()
    }

    /// Every way the policy will meet the arm otherwise than it learnt: for the operator's
    /// warnings before anything moves.
    pub fn mismatches(&self) -> Vec<String> {
        [
            self.motion_mismatch(),
            self.io.speed_scale_mismatch(&self.options.safety),
            self.io.gripper_mismatch(),
            self.observation_mismatch(),
            self.io.camera_mismatch(&self.calibration),
            self.io.wrist_camera_mismatch(&self.calibration),
        ]
        .into_iter()
        .flatten()
        .collect()
    }

    /// The home pose in robot degrees.
    pub fn home_deg(&self) -> [f64; 6] {
        self.calibration.to_robot(&self.io.nominal.q)
    }

    /// Runs every episode; a fault stops the arm and ends the run (see [`RunReport::fault`]).
    /// Live, Ctrl-C sends StopMotion at once over a second line whatever the loop waits on
    /// ([`interrupt`]).
    pub fn run(
        &mut self,
        host: &mut dyn EpisodeHost,
        pose: &mut dyn PoseSource,
    ) -> Result<RunReport> {
        let line = self.link.side_line();
        let interrupt = self.interrupt.clone();
        let done = AtomicBool::new(false);
        let (outcome, watched) = std::thread::scope(|s| {
            let watcher = line
                .as_deref()
                .map(|line| s.spawn(|| interrupt::watch(&interrupt, &done, line)));
            let outcome = self.episodes(host, pose);
            done.store(true, Ordering::Relaxed);
            (outcome, watcher.and_then(|w| w.join().ok().flatten()))
        });
        if let Some(w) = watched {
            self.link.log.note(
                "interrupt_stop",
                serde_json::json!({
                    "ms": w.took.as_secs_f64() * 1000.0,
                    "error": w.result.err(),
                }),
            );
        }
        let (episodes, fault) = outcome?;
        let fault = fault.map(|f| {
            self.link.stop(&f);
            self.root_cause(f)
        });
        self.link.log.flush();
        Ok(RunReport {
            episodes,
            fault,
            stopped_in: self.link.stopped_in(),
        })
    }

    /// The episodes, until the last or a fault.
    fn episodes(
        &mut self,
        host: &mut dyn EpisodeHost,
        pose: &mut dyn PoseSource,
    ) -> Result<(Vec<EpisodeReport>, Option<Fault>)> {
        let mut episodes = Vec::new();
        if let (Some(space), None) = (self.policy.image_space(), &self.camera) {
            return Err(DeployError::config(
                "camera feed",
                format!(
                    "the model reads camera images ({}): give it a camera feed (--camera-tcp)",
                    space.describe()
                ),
            ));
        }
        if let Err(fault) = self.prepare() {
            return Ok((episodes, Some(fault)));
        }
        while (episodes.len() as u32) < self.options.episodes {
            let index = episodes.len() as u32;
            if let Err(e) = host.begin(index) {
                if self.interrupt.load(Ordering::Relaxed) {
                    return Ok((episodes, Some(Fault::Interrupted)));
                }
                return Err(e);
            }
            match self.episode(index, pose) {
                Ok(mut report) => {
                    report.success = host.outcome()?;
                    let verdict = match report.success {
                        Some(true) => "grasped",
                        Some(false) => "failed",
                        None => "done",
                    };
                    let ended = if report.ended_at_success {
                        " (success rule held: ended)"
                    } else {
                        ""
                    };
                    println!(
                        "episode {}: {verdict} after {} steps{ended}",
                        index + 1,
                        report.steps
                    );
                    self.link
                        .log
                        .note("episode", serde_json::json!(format!("{report:?}")));
                    episodes.push(report);
                }
                Err(fault) => return Ok((episodes, Some(fault))),
            }
        }
        Ok((episodes, self.link.settle_aside(true).err()))
    }

    /// A refused call is often the echo of a state the stream had not shown yet (an e-stop, a
    /// safety stop, a collision, a fault code) or of the stream's own failure: once the arm is stopped,
    /// look at the stream for up to 50 ms and name that state instead.
    fn root_cause(&mut self, fault: Fault) -> Fault {
        if !matches!(fault, Fault::CallFailed { .. }) {
            return fault;
        }
        // The call the StopMotion of Ctrl-C aborted (a MoveJ answers 14).
        if self.interrupt.load(Ordering::Relaxed) {
            return Fault::Interrupted;
        }
        let until = self.link.now() + Duration::from_millis(50);
        while self.link.now() < until {
            match self.link.state() {
                Ok(s) => {
                    if let Err(
                        f @ (Fault::EmergencyStop
                        | Fault::SafetyStop(_)
                        | Fault::Collision
                        | Fault::ControllerFault { .. }),
                    ) = self.watchdog.check(&s, self.link.now())
                    {
                        return f;
                    }
                }
                Err(f) => return f,
            }
            let later = self.link.now() + Duration::from_millis(2);
            self.link.sleep_until(later);
        }
        fault
    }

    /// Enables the arm in automatic mode, sets the controller's global speed override to the
    /// safety caps' share of the top speed, and activates the gripper when needed.
    ///
    /// The override cannot be read back (no call or stream field carries it), and it slows
    /// servo motion as well as MoveJ: left as the pendant set it, a low override would make the
    /// arm fall behind the stream. Set to the caps' share, the controller enforces the same speed
    /// as the safety filter, a second cap that does not rest on this program; it stays set after
    /// the run.
    fn prepare(&mut self) -> std::result::Result<(), Fault> {
        let state = self.checked_state()?;
        if !state.state.enabled {
            self.link
                .send(&RobotCommand::RobotEnable { enable: true })?;
        }
        if state.state.robot_mode != 0 {
            self.link.send(&RobotCommand::Mode { mode: 0 })?;
        }
        let percent = self.filter.speed_override_percent();
        self.link.send(&RobotCommand::SetSpeed { percent })?;
        if !state.state.gripper_active {
            self.link.send(&RobotCommand::ActGripper {
                index: self.options.gripper_index,
                activate: true,
            })?;
        }
        Ok(())
    }

    fn checked_state(&mut self) -> std::result::Result<crate::robot::StampedState, Fault> {
        if self.interrupt.load(Ordering::Relaxed) {
            return Err(Fault::Interrupted);
        }
        let s = self.link.state()?;
        self.watchdog.check(&s, self.link.now())?;
        Ok(s)
    }

    /// Commands the gripper without waiting for the reply, so the servo set points keep
    /// flowing (a reply takes the controller's latency, more than a servo period).
    fn gripper(&mut self, open: bool) -> std::result::Result<(), Fault> {
        self.link.send_aside(&RobotCommand::MoveGripper {
            index: self.options.gripper_index,
            position_percent: if open { 100 } else { 0 },
            // The speed scale slows the gripper as it slows the arm: at 0.25 with the gripper
            // at full speed, one control step (133 ms) let a flickering close command shut
            // the fingers that training's 33 ms steps only started, and a kinematic-drive
            // policy shoved the cube to the workspace box's edge on the twin.
            speed_percent: (100.0 * self.options.safety.speed_scale)
                .round()
                .clamp(1.0, 100.0) as u8,
            force_percent: 50,
            max_time_ms: 3000,
        })
    }

    /// MoveJ to the model's home pose: its whole path checked first (soft limits, the TCP's
    /// box, the arm's clearance), at the speed and acceleration caps in force.
    fn go_home(&mut self) -> std::result::Result<(), Fault> {
        let home = self.home_deg();
        let now = self.checked_state()?.state.joints_deg;
        self.filter.check_path(&now, &home)?;
        let (speed, acc, _) = self.filter.caps();
        // The controller scales MoveJ's speed and acceleration by the override too.
        let factor = 100.0 / self.filter.speed_override_percent() as f64;
        self.link.send(&RobotCommand::MoveJ {
            joints_deg: home,
            speed_percent: (100.0 * speed / fr5::MOVE_J_FULL_SPEED_DEG_S * factor).min(100.0),
            acc_percent: (100.0 * acc / fr5::MOVE_J_FULL_ACC_DEG_S2[0] * factor).min(100.0),
        })
    }

    /// Streams set points towards `target` on the servo schedule until tick `until`: each send
    /// waits for its tick, checks the state (but the first when `read` says the caller has
    /// just read it), and carries the filter's set point for every tick due by then.
    fn stream(
        &mut self,
        clock: &mut ServoClock,
        target: &[f64; 6],
        until: u64,
        read: bool,
    ) -> std::result::Result<(), Fault> {
        let mut first = read;
        while clock.taken() < until {
            self.link.sleep_until(clock.next_due());
            if !first {
                self.checked_state()?;
            }
            first = false;
            self.link.settle_aside(false)?;
            let n = clock.take_due(self.link.now(), until);
            let mut set_point = self.filter.next(target)?;
            for _ in 1..n {
                set_point = self.filter.next(target)?;
            }
            self.link.send(&RobotCommand::ServoJ {
                joints_deg: set_point,
                cmd_t: (self.tick.as_secs_f64() * n as f64).min(MAX_CMD_T),
            })?;
        }
        Ok(())
    }

    /// Brakes the arm to rest on the servo schedule (the filter's braking, every joint as hard as
    /// allowed), so a servo session never ends with the set points still moving.
    fn come_to_rest(&mut self, clock: &mut ServoClock) -> std::result::Result<(), Fault> {
        while let Some(mut set_point) = self.filter.brake() {
            self.link.sleep_until(clock.next_due());
            self.checked_state()?;
            self.link.settle_aside(false)?;
            let n = clock.take_due(self.link.now(), u64::MAX);
            for _ in 1..n {
                match self.filter.brake() {
                    Some(next) => set_point = next,
                    None => break,
                }
            }
            self.link.send(&RobotCommand::ServoJ {
                joints_deg: set_point,
                cmd_t: (self.tick.as_secs_f64() * n as f64).min(MAX_CMD_T),
            })?;
        }
        Ok(())
    }

    /// Streams set points along the straight joint line from the last set point to `goal` at
    /// `speed` (deg/s, the joint that moves farthest), then holds `goal` until the filter's set
    /// point has arrived there at rest or `settle` has passed.
    fn stream_to(
        &mut self,
        clock: &mut ServoClock,
        goal: &[f64; 6],
        speed: f64,
        settle: Duration,
    ) -> std::result::Result<(), Fault> {
        let from = self.filter.last().map_or(*goal, |(at, _)| at);
        let farthest = (0..6).fold(0.0_f64, |m, j| m.max((goal[j] - from[j]).abs()));
        let ticks = (farthest / speed / self.tick.as_secs_f64()).ceil() as u64;
        for k in 1..=ticks {
            let s = k as f64 / ticks as f64;
            let target = std::array::from_fn(|j| from[j] + s * (goal[j] - from[j]));
            let until = clock.taken() + 1;
            self.stream(clock, &target, until, false)?;
        }
        let end = clock.taken() + (settle.as_secs_f64() / self.tick.as_secs_f64()).ceil() as u64;
        while clock.taken() < end {
            let until = clock.taken() + 1;
            self.stream(clock, goal, until, false)?;
            if let Some((at, speed)) = self.filter.last() {
                let gap = (0..6).fold(0.0_f64, |m, j| m.max((at[j] - goal[j]).abs()));
                if gap < ARRIVED_DEG && speed.iter().all(|v| v.abs() < ARRIVED_DEG_S) {
                    break;
                }
            }
        }
        Ok(())
    }

    /// Lowers a grasped object to where the gripper closed on it, opens the gripper while the
    /// set points hold the arm there, and withdraws to where the arm held the object: so a
    /// successful episode ends with the object back on the table, not dropped from the lift.
    fn put_down(
        &mut self,
        clock: &mut ServoClock,
        down: &[f64; 6],
    ) -> std::result::Result<(), Fault> {
        let Some((lifted, _)) = self.filter.last() else {
            return Ok(());
        };
        let speed = PUT_DOWN_DEG_S * self.options.safety.speed_scale;
        self.stream_to(clock, down, speed, SETTLE_LIMIT)?;
        self.gripper(true)?;
        self.link.settle_aside(true)?;
        let opened = self.link.now() + GRIPPER_OPEN_LIMIT;
        loop {
            self.stream_to(clock, down, speed, self.tick)?;
            let state = self.link.state()?.state;
            if state.gripper_position >= GRIPPER_OPEN_PERCENT || self.link.now() >= opened {
                break;
            }
        }
        self.stream_to(clock, &lifted, speed, SETTLE_LIMIT)
    }

    /// One episode from home: returns when its steps are done, or the fault.
    fn episode(
        &mut self,
        index: u32,
        pose: &mut dyn PoseSource,
    ) -> std::result::Result<EpisodeReport, Fault> {
        self.go_home()?;
        self.gripper(true)?;
        let first = pose
            .wait_first(self.options.pose_timeout)
            .map_err(|e| Fault::StreamFailed(format!("object pose: {e}")))?;
        let mut object = first.message;
        let mut images = match &mut self.camera {
            Some(frames) => Some(
                frames
                    .wait_first(self.options.pose_timeout)
                    .map_err(|e| Fault::StreamFailed(format!("camera: {e}")))?,
            ),
            None => None,
        };
        let start = self.checked_state()?;
        self.filter.start(&start.state.joints_deg)?;
        self.link.send(&RobotCommand::ServoMoveStart)?;

        let mut reader = ArmReader::new(self.options.safety.speed_scale);
        let mut closing = false;
        let mut state = reader.estimate(
            &self.io,
            &self.calibration,
            &start.state,
            &object,
            closing,
            self.link.now(),
        );
        let mut command = self.io.hold(&state);
        let mut shown = vec![0.0; self.policy.act_dim()];
        let steps = self.options.max_steps.unwrap_or(self.io.max_steps);
        let mut ik_failures = 0;
        let mut success = self.io.success_judge();
        let mut acted = steps;
        let mut succeeded = false;
        // Where the arm was when the gripper last began to close: where a grasped object
        // goes back down to.
        let mut closed_at = None;
        let mut clock = ServoClock::new(self.link.now(), self.tick);
        for step in 0..steps {
            if step > 0 {
                // The step begins when its first tick is due: the policy acts at its trained
                // period however the replies went.
                self.link.sleep_until(clock.next_due());
                let reading = self.checked_state()?;
                if let Some(p) = pose
                    .latest()
                    .map_err(|e| Fault::StreamFailed(format!("object pose: {e}")))?
                {
                    let age = self.link.now().saturating_duration_since(p.received_at);
                    let deadline_ms = self.options.safety.pose_deadline_ms;
                    if age.as_secs_f64() * 1000.0 > deadline_ms {
                        return Err(Fault::StalePose {
                            age_ms: age.as_secs_f64() * 1000.0,
                            deadline_ms,
                        });
                    }
                    object = p.message;
                }
                if let Some(frames) = &mut self.camera {
                    images = (frames.latest())
                        .map_err(|e| Fault::StreamFailed(format!("camera: {e}")))?
                        .or(images);
                }
                state = reader.estimate(
                    &self.io,
                    &self.calibration,
                    &reading.state,
                    &object,
                    closing,
                    self.link.now(),
                );
                if self.options.end_at_success && success.update(&state) {
                    acted = step;
                    succeeded = true;
                    let target = self.calibration.to_robot(&command.arm_target);
                    for k in 0..self.options.hold_after_success as u64 {
                        let until = (step as u64 + k + 1) * self.servo_ticks as u64;
                        self.stream(&mut clock, &target, until, k == 0)?;
                    }
                    break;
                }
            }
            let obs = (self.io).observe(&state, &shown, self.options.safety.speed_scale);
            if let Some(i) = &images {
                let age = self.link.now().saturating_duration_since(i.received_at);
                let deadline_ms = self.options.safety.frame_deadline_ms;
                if age.as_secs_f64() * 1000.0 > deadline_ms {
                    return Err(Fault::StaleFrames {
                        age_ms: age.as_secs_f64() * 1000.0,
                        deadline_ms,
                    });
                }
            }
            let pixels = images.as_ref().map(|i| i.bytes.as_slice());
            let output = (self.policy.act_with_images(&obs, pixels, true)).map_err(|e| {
                Fault::CallFailed {
                    call: "policy".into(),
                    message: e.to_string(),
                }
            })?;
            if let Some(i) = output.iter().position(|v| !v.is_finite()) {
                return Err(Fault::NonFiniteOutput {
                    index: i,
                    value: output[i],
                });
            }
            self.link.log.step(index, step, &obs, &output);
            let (action, next_shown) =
                self.io.env_action(&output).map_err(|e| Fault::CallFailed {
                    call: "policy action".into(),
                    message: e.to_string(),
                })?;
            shown = next_shown;
            if !self.io.apply(&state, &action, &mut command) {
                ik_failures += 1;
            }
            if closing == command.gripper_open {
                closing = !command.gripper_open;
                if closing {
                    closed_at = Some(self.calibration.to_robot(&command.arm_target));
                }
                self.gripper(command.gripper_open)?;
            }
            let target = self.calibration.to_robot(&command.arm_target);
            let until = (step as u64 + 1) * self.servo_ticks as u64;
            self.stream(&mut clock, &target, until, true)?;
        }
        let hold = succeeded && self.options.after_success == AfterSuccess::Hold;
        if let (true, AfterSuccess::PutDown, Some(down)) =
            (succeeded, self.options.after_success, closed_at)
        {
            self.put_down(&mut clock, &down)?;
        }
        self.come_to_rest(&mut clock)?;
        self.link.settle_aside(true)?;
        self.link.send(&RobotCommand::ServoMoveEnd)?;
        if !hold {
            self.gripper(true)?;
        }
        Ok(EpisodeReport {
            steps: acted,
            ended_at_success: acted < steps,
            success: None,
            ik_failures,
        })
    }
}
