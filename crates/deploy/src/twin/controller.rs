//! The FAIRINO controller's behaviour as a state machine, without any networking: what each
//! remote call does to the robot and what it answers. The simulation feeds it measurements
//! ([`Controller::observe`]) and reads its joint and gripper set points
//! ([`Controller::setpoint`]); the XML-RPC service calls the typed methods. Time is given by the
//! caller in seconds, so tests can drive it with a perfect plant and no clock.
//!
//! # Behaviour
//! - **Start state** (see [`StartState`]): powered on, drives enabled, automatic mode, global
//!   speed 100 %, no fault, the gripper *not* activated (a real gripper needs `ActGripper` after
//!   power-on), arm holding its home pose.
//! - **Motion gating**, in this order: e-stop pressed → 31; safety stop → 99; a fault in
//!   `main_code` → 14; drives disabled → 101; manual mode → 14. It applies to `MoveJ`,
//!   `ServoMoveStart` and `ServoJ`; `MoveGripper` is gated by the e-stop and the safety stop
//!   only (the gripper is a peripheral).
//! - **`MoveJ`**: joint targets inside the limits (else 4), `vel` and `ovl` in (0, 100] % (else
//!   4), scaled by `SetSpeed`'s global %, a synchronised minimum-jerk move within the FR5's joint
//!   speed and acceleration limits. Moves queue behind each other; each gets a ticket whose
//!   outcome (0 arrived, or the code of what stopped it) the caller can wait for. It is done when
//!   the profile has ended and the arm has settled (joints within 2° of the target and slower
//!   than 1°/s), or [`ControllerConfig::settle_timeout`] after the profile's end. Refused with 14
//!   during a servo session.
//! - **Servo**: `ServoJ` outside a `ServoMoveStart`…`ServoMoveEnd` session → 14; `cmdT` outside
//!   0.001…0.016 s → 4. A target beyond the joint limits, or one further from the previous
//!   target (the set point, for a session's first) than the joint's top speed
//!   ([`fr5::MAX_SPEED_DEG_S`], plus [`ControllerConfig::servo_speed_tolerance`]) covers in
//!   `cmdT`, is the controller's error: the call answers 29, `main_code` 29 shows with the
//!   joint in `sub_code` (1–6 past a limit, 11–16 too fast: [`MAIN_CODE_SERVOJ_OVER_LIMIT`]),
//!   and the arm brakes. Each accepted target is reached along a straight line over `cmdT`,
//!   the set point never faster than the joint's top speed times `SetSpeed`'s global %: a
//!   stream faster than the override allows falls behind its targets (chosen: FAIRINO does not
//!   document how the override acts on `ServoJ`; industrial controllers' overrides scale the
//!   commanded speed, and a cap keeps the stream's own timing).
//! - **`StopMotion`** aborts every move (a waiting `MoveJ` returns 14) and the servo session.
//!   A fault, the e-stop (31), a safety stop (99), disabling (101) or manual mode (14) abort the
//!   same way, with their code.
//! - **Braking**: an aborted motion does not stop dead. The set point decelerates from its
//!   speed at [`ControllerConfig::brake_decel_deg_s2`], every joint stopping at the same
//!   moment (along the path it was on), so the arm overshoots where it was stopped by v²/2a;
//!   the drives' lag adds to it. The arm reports moving until the brake ends; a `MoveJ` sent
//!   meanwhile starts after it, `ServoMoveStart` is refused (14).
//! - **Drives** ([`ControllerConfig::tracking`]): the set point reaches each joint after a
//!   pure delay and a first-order lag (off by default: the simulated arm follows the set
//!   point directly). [`Controller::setpoint`] is what the drives command, so the reported
//!   joints and speeds are the arm's, lag included. A joint further than
//!   [`ControllerConfig::following_error_deg`] from its set point is a following error:
//!   `main_code` 200 ([`MAIN_CODE_FOLLOWING_ERROR`], chosen: FAIRINO documents no number),
//!   `sub_code` the joint, and the arm brakes.
//! - **Faults**: `main_code`/`sub_code` of the state. The e-stop sets main code 31, sub code 1
//!   ([`MAIN_CODE_EMERGENCY_STOP`]), which `ResetAllError` clears once the button is released
//!   (while pressed: 14). An injected fault is resettable unless injected otherwise (then 30);
//!   the ServoJ and following-error faults are resettable.
//!   Safety stops show in their own flags, not in `main_code`.
//! - **Gripper**: `ActGripper(index 1…8, 1)` activates, `(…, 0)` resets; `MoveGripper` before
//!   activation → 73; position, speed and force in 0…100 % (else 4); `maxtime` 0…30000 ms (0:
//!   30 s). The set point moves at the speed % of the simulated fingers' own speed
//!   ([`fairgrasp_sim::control::FINGERS_FULL_SPEED_PERCENT_PER_S`]); the force % is the
//!   fingers' squeezing force (50 % the simulated drive's own, see [`super::world`]).
//!   Motion done on arrival, on a stall (an object between the fingers) or after `maxtime`;
//!   stalled short of a closing target it holds: the gripper's current reads the force %
//!   (see [`super::gripper`]).
//! - **Collision detection** ([`ControllerConfig::collision_level_n`]): a net contact force on
//!   the robot above the level (see [`super::world`] for what counts) sets `collision_state`,
//!   raises [`MAIN_CODE_COLLISION`] with the joint carrying the link that pressed hardest in
//!   `sub_code`, and the arm brakes. `ResetAllError` clears both; detection then waits for the
//!   force to fall below the level, so an arm still pressing can be moved clear.
//! - **Kinematics**: the simulator's chain from the arm base to the gripper's centre point (the
//!   TCP as if the gripper were configured as the tool). Poses are `[x, y, z, rx, ry, rz]` in mm
//!   and degrees, base frame, `R = Rz(rz)·Ry(ry)·Rx(rx)` (fixed X-Y-Z angles). IK failure → 28.

use super::faults::TrackingModel;
use super::gripper::Gripper;
use super::motion::{Brake, Drives, Joints, Profile, ServoStep, max_gap, rate_limited};
use crate::fairino::error_codes::codes;
use crate::fairino::fr5;
use crate::robot::RobotState;
use fairgrasp_sim::kinematics::SerialChain;
use fairgrasp_sim::rapier3d::na::{Isometry3, Translation3, UnitQuaternion};
use std::collections::VecDeque;

/// `(main_code, sub_code)` while the e-stop is pressed, and after until reset.
pub const MAIN_CODE_EMERGENCY_STOP: (i32, i32) = (31, 1);

/// `main_code` of a refused ServoJ: the call's own code 29; `sub_code` is the joint (1–6) past
/// its limit, or 10 + the joint that would move too fast.
pub const MAIN_CODE_SERVOJ_OVER_LIMIT: i32 = 29;

/// `main_code` of a following error, `sub_code` the joint (1–6). FAIRINO documents no number
/// for it; the twin's choice, outside the documented ones.
pub const MAIN_CODE_FOLLOWING_ERROR: i32 = 200;

/// `main_code` of a collision the controller detected, `sub_code` the arm joint (1–6) that
/// carries the link pressing hardest (0 for a forced one). FAIRINO documents `collision_state`
/// in the stream but no code for it; the twin's choice, next to the following error's.
pub const MAIN_CODE_COLLISION: i32 = 201;

/// The collision level by default (N of net external force on the robot): FAIRINO documents
/// levels 1–10 per joint (`SetAnticollision`) but no forces, so this is the twin's choice: a
/// lenient one that leaves earlier transfer figures comparable (the deployment policy's 200
/// deployment-matched episodes trip it in none; at 250 N, 3 at speed scale 0.25), well below
/// the fingertips driven into the table at 20 % speed (over 600 N). `--strict` sets 150 N.
pub const DEFAULT_COLLISION_LEVEL_N: f64 = 400.0;

/// The ServoJ speed tolerance by default: 5 % over the published top speed.
pub const DEFAULT_SERVO_SPEED_TOLERANCE: f64 = 0.05;
/// The braking deceleration by default (deg/s²): FAIRINO publishes none; 720 stops a joint from
/// its top speed in a quarter second.
pub const DEFAULT_BRAKE_DECEL_DEG_S2: f64 = 720.0;
/// The following-error limit by default (deg): see [`ControllerConfig::following_error_deg`].
pub const DEFAULT_FOLLOWING_ERROR_DEG: f64 = 20.0;

/// How the controller is found at power-on.
#[derive(Clone, Debug, PartialEq)]
pub struct StartState {
    /// Drives enabled.
    pub enabled: bool,
    /// Automatic mode (remote motion allowed); manual otherwise.
    pub automatic: bool,
    /// Gripper already activated.
    pub gripper_active: bool,
}

impl Default for StartState {
    fn default() -> Self {
        Self {
            enabled: true,
            automatic: true,
            gripper_active: false,
        }
    }
}

/// Limits and timing of the controller.
#[derive(Clone, Debug, PartialEq)]
pub struct ControllerConfig {
    /// Joint limits (deg).
    pub limits_deg: [(f64, f64); 6],
    /// Each joint's top speed (deg/s): what ServoJ steps are checked against, and a MoveJ's at
    /// 100 %.
    pub max_speed_deg: Joints,
    /// Each joint's MoveJ acceleration at `acc` 100 % (deg/s²).
    pub max_acc_deg: Joints,
    /// A move counts as done this long after its profile ended, settled or not (s).
    pub settle_timeout: f64,
    /// How the controller is found at power-on.
    pub start: StartState,
    /// How far a ServoJ step may exceed the top speed, as a share of it.
    pub servo_speed_tolerance: f64,
    /// The set point's deceleration when the arm stops (deg/s²).
    pub brake_decel_deg_s2: f64,
    /// The largest gap between a joint's set point and the joint before it is a fault (deg);
    /// `None`: not checked.
    pub following_error_deg: Option<f64>,
    /// How the drives follow their set points.
    pub tracking: TrackingModel,
    /// Net external force on the robot (N) above which the controller detects a collision;
    /// `None`: detection off.
    pub collision_level_n: Option<f64>,
}

impl ControllerConfig {
    /// The FR5's speeds with joint limits `limits_rad` (from the robot model).
    pub fn fr5(limits_rad: &[(f64, f64)], start: StartState) -> Self {
        Self {
            limits_deg: std::array::from_fn(|j| {
                let (lo, hi) = limits_rad.get(j).copied().unwrap_or((-3.05, 3.05));
                (lo.to_degrees(), hi.to_degrees())
            }),
            max_speed_deg: fr5::MAX_SPEED_DEG_S,
            max_acc_deg: fr5::MOVE_J_FULL_ACC_DEG_S2,
            settle_timeout: 1.0,
            start,
            servo_speed_tolerance: DEFAULT_SERVO_SPEED_TOLERANCE,
            brake_decel_deg_s2: DEFAULT_BRAKE_DECEL_DEG_S2,
            following_error_deg: Some(DEFAULT_FOLLOWING_ERROR_DEG),
            tracking: TrackingModel::default(),
            collision_level_n: Some(DEFAULT_COLLISION_LEVEL_N),
        }
    }
}

/// What the simulation measured.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Measured {
    /// Joint angles (deg).
    pub joints_deg: Joints,
    /// Joint speeds (deg/s).
    pub joint_speeds_deg: Joints,
    /// Gripper opening, % of the stroke.
    pub gripper_percent: f64,
    /// The net force of everything outside the robot on it (N): what collision detection feels.
    pub contact_force_n: f64,
    /// The arm joint (1–6) carrying the link that presses hardest; 0 when nothing touches.
    pub contact_joint: i32,
}

/// What the simulation should track.
#[derive(Clone, Debug, PartialEq)]
pub struct Setpoint {
    /// Joint set points (deg).
    pub joints_deg: Joints,
    /// Gripper opening set point, % of the stroke.
    pub gripper_percent: f64,
    /// The force the fingers squeeze with, % (`MoveGripper`'s force).
    pub gripper_force_percent: f64,
}

#[derive(Clone, Debug)]
struct Fault {
    main: i32,
    sub: i32,
    resettable: bool,
}

#[derive(Clone, Debug)]
struct QueuedMove {
    ticket: u64,
    target: Joints,
    /// Shares of the top joint speed and acceleration.
    speed_scale: f64,
    acc_scale: f64,
}

#[derive(Clone, Debug)]
struct ActiveMove {
    ticket: u64,
    profile: Profile,
}

/// Outcomes kept for waiting callers; older ones are forgotten.
const OUTCOMES_KEPT: usize = 256;
/// ServoJ targets kept for the state's `last_servoJ_target`: many more than arrive between
/// two measurements.
const SERVO_TARGETS_KEPT: usize = 16;

/// The controller (see the [module](self) documentation).
#[derive(Clone, Debug)]
pub struct Controller {
    config: ControllerConfig,
    chain: SerialChain,
    enabled: bool,
    automatic: bool,
    speed_percent: f64,
    estop: bool,
    safety: [bool; 2],
    fault: Option<Fault>,
    setpoint: Joints,
    setpoint_time: f64,
    /// The set point's speed (deg/s).
    velocity: Joints,
    brake: Option<Brake>,
    drives: Drives,
    /// When the latest measurement was taken (s): the clock the state reports.
    measured_at: f64,
    active: Option<ActiveMove>,
    queue: VecDeque<QueuedMove>,
    servo_session: bool,
    servo_step: Option<ServoStep>,
    /// The last target of the servo session, what the next step is measured from.
    servo_reference: Option<Joints>,
    /// The ServoJ targets accepted lately with when (s), for the state's `last_servoJ_target`:
    /// a state reports the last one accepted by its own clock.
    servo_targets: VecDeque<(f64, Joints)>,
    /// The target accepted before the oldest of `servo_targets`.
    servo_target_before: Joints,
    next_ticket: u64,
    outcomes: VecDeque<(u64, i32)>,
    measured: Measured,
    gripper: Gripper,
    motion_commands: u64,
    /// `collision_state`: a collision was detected (or forced) and not yet reset, and when.
    collision: bool,
    collision_at: f64,
    /// Detection waits for the contact force to fall below the level after a collision, so a
    /// reset arm still pressing can be moved clear.
    collision_armed: bool,
}

/// A TCP pose as the controller reports it: mm and degrees, fixed X-Y-Z angles.
pub fn pose_to_wire(pose: &Isometry3<f64>) -> [f64; 6] {
    let t = pose.translation.vector * 1000.0;
    let (rx, ry, rz) = pose.rotation.euler_angles();
    [
        t.x,
        t.y,
        t.z,
        rx.to_degrees(),
        ry.to_degrees(),
        rz.to_degrees(),
    ]
}

/// The inverse of [`pose_to_wire`].
pub fn wire_to_pose(p: &[f64; 6]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p[0] / 1000.0, p[1] / 1000.0, p[2] / 1000.0),
        UnitQuaternion::from_euler_angles(p[3].to_radians(), p[4].to_radians(), p[5].to_radians()),
    )
}

fn finite(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}

impl Controller {
    /// A controller at power-on, holding `home_deg`. `chain` goes from the arm base to the TCP.
    pub fn new(config: ControllerConfig, chain: SerialChain, home_deg: Joints, now: f64) -> Self {
        let start = config.start.clone();
        Self {
            config,
            chain,
            enabled: start.enabled,
            automatic: start.automatic,
            speed_percent: 100.0,
            estop: false,
            safety: [false; 2],
            fault: None,
            setpoint: home_deg,
            setpoint_time: now,
            velocity: [0.0; 6],
            brake: None,
            drives: Drives::new(home_deg, now),
            measured_at: now,
            active: None,
            queue: VecDeque::new(),
            servo_session: false,
            servo_step: None,
            servo_reference: None,
            servo_targets: VecDeque::new(),
            servo_target_before: [0.0; 6],
            next_ticket: 1,
            outcomes: VecDeque::new(),
            measured: Measured {
                joints_deg: home_deg,
                joint_speeds_deg: [0.0; 6],
                gripper_percent: 100.0,
                ..Measured::default()
            },
            gripper: Gripper::new(start.gripper_active),
            motion_commands: 0,
            collision: false,
            collision_at: 0.0,
            collision_armed: true,
        }
    }

    /// The limits and timing it runs with.
    pub fn config(&self) -> &ControllerConfig {
        &self.config
    }

    // ── Gating and aborting ────────────────────────────────────────────────

    /// Why arm motion is refused now, if it is.
    pub fn motion_refusal(&self) -> Option<i32> {
        if self.estop {
            Some(codes::EMERGENCY_STOP)
        } else if self.safety.iter().any(|&s| s) {
            Some(codes::SAFETY_STOP)
        } else if self.fault.is_some() {
            Some(codes::EXECUTION_FAILED)
        } else if !self.enabled {
            Some(codes::NOT_ENABLED)
        } else if !self.automatic {
            Some(codes::EXECUTION_FAILED)
        } else {
            None
        }
    }

    fn record(&mut self, ticket: u64, code: i32) {
        if self.outcomes.len() >= OUTCOMES_KEPT {
            self.outcomes.pop_front();
        }
        self.outcomes.push_back((ticket, code));
    }

    /// Stops every motion, braking from the set point's speed now; waiting moves end with
    /// `code`.
    fn abort(&mut self, now: f64, code: i32) {
        self.advance(now);
        if let Some(active) = self.active.take() {
            self.record(active.ticket, code);
        }
        while let Some(queued) = self.queue.pop_front() {
            self.record(queued.ticket, code);
        }
        self.servo_session = false;
        self.servo_step = None;
        self.servo_reference = None;
        if self.brake.is_none() {
            self.brake = Brake::new(
                self.setpoint,
                self.velocity,
                self.setpoint_time,
                self.config.brake_decel_deg_s2,
            );
        }
    }

    /// The controller's own error: a resettable fault, the arm brakes.
    fn raise(&mut self, now: f64, main: i32, sub: i32) {
        self.set_fault(now, main, sub, true);
    }

    /// The outcome of move `ticket`: `None` while it is queued or moving; a code once it ended
    /// (also for tickets too old to remember: [`codes::OK`]).
    pub fn outcome(&self, ticket: u64) -> Option<i32> {
        if let Some((_, code)) = self.outcomes.iter().rev().find(|(t, _)| *t == ticket) {
            return Some(*code);
        }
        let pending = self.active.as_ref().is_some_and(|a| a.ticket == ticket)
            || self.queue.iter().any(|q| q.ticket == ticket);
        (!pending).then_some(codes::OK)
    }

    // ── Power, mode, speed, faults ─────────────────────────────────────────

    /// `RobotEnable(1|0)`.
    pub fn enable(&mut self, now: f64, on: bool) -> i32 {
        if on && self.estop {
            return codes::EMERGENCY_STOP;
        }
        if !on {
            self.abort(now, codes::NOT_ENABLED);
        }
        self.enabled = on;
        codes::OK
    }

    /// `Mode(0 automatic | 1 manual)`.
    pub fn set_mode(&mut self, now: f64, mode: i64) -> i32 {
        match mode {
            0 => self.automatic = true,
            1 => {
                self.abort(now, codes::EXECUTION_FAILED);
                self.automatic = false;
            }
            _ => return codes::PARAM_VALUE,
        }
        codes::OK
    }

    /// `SetSpeed(1…100)`: the global speed override (%).
    pub fn set_speed(&mut self, percent: f64) -> i32 {
        if !(1.0..=100.0).contains(&percent) {
            return codes::PARAM_VALUE;
        }
        self.speed_percent = percent;
        codes::OK
    }

    /// `ResetAllError()`.
    pub fn reset_errors(&mut self) -> i32 {
        if self.estop {
            return codes::EXECUTION_FAILED;
        }
        match &self.fault {
            Some(f) if !f.resettable => codes::NOT_RESETTABLE,
            _ => {
                self.fault = None;
                self.collision = false;
                codes::OK
            }
        }
    }

    /// Presses (`true`) or releases the e-stop.
    pub fn set_estop(&mut self, now: f64, pressed: bool) {
        if pressed && !self.estop {
            self.abort(now, codes::EMERGENCY_STOP);
            let (main, sub) = MAIN_CODE_EMERGENCY_STOP;
            self.fault = Some(Fault {
                main,
                sub,
                resettable: true,
            });
        }
        self.estop = pressed;
    }

    /// Sets the two safety-stop inputs; a rising one stops the arm.
    pub fn set_safety_stop(&mut self, now: f64, inputs: [bool; 2]) {
        if inputs
            .iter()
            .zip(&self.safety)
            .any(|(&new, &old)| new && !old)
        {
            self.abort(now, codes::SAFETY_STOP);
        }
        self.safety = inputs;
    }

    /// A collision: `collision_state` 1, [`MAIN_CODE_COLLISION`] with `joint` as the sub code,
    /// the arm brakes. `false` clears the collision state and its fault.
    pub fn set_collision(&mut self, now: f64, on: bool, joint: i32) {
        if !on {
            self.collision = false;
            if self
                .fault
                .as_ref()
                .is_some_and(|f| f.main == MAIN_CODE_COLLISION)
            {
                self.fault = None;
            }
            return;
        }
        self.raise(now, MAIN_CODE_COLLISION, joint);
        self.collision = true;
        self.collision_at = now;
        self.collision_armed = false;
    }

    /// When the collision standing now was detected (twin time, s).
    pub fn collision_since(&self) -> Option<f64> {
        self.collision.then_some(self.collision_at)
    }

    /// Raises a fault (`main` ≠ 0: the arm stops) or clears it (`main` = 0).
    pub fn set_fault(&mut self, now: f64, main: i32, sub: i32, resettable: bool) {
        if main == 0 {
            self.fault = None;
            self.collision = false;
            return;
        }
        self.abort(now, codes::EXECUTION_FAILED);
        self.fault = Some(Fault {
            main,
            sub,
            resettable,
        });
    }

    // ── Arm motion ─────────────────────────────────────────────────────────

    fn within_limits(&self, q: &Joints) -> bool {
        self.outside_limits(q).is_none()
    }

    /// The first joint of `q` outside its limits.
    fn outside_limits(&self, q: &Joints) -> Option<usize> {
        q.iter()
            .zip(&self.config.limits_deg)
            .position(|(v, (lo, hi))| !(v.is_finite() && *v >= lo - 1e-9 && *v <= hi + 1e-9))
    }

    /// `MoveJ`: queues a move to `target` at `vel` % of the top joint speed and `acc` % of the
    /// top acceleration, both times `ovl` % and the global override (`acc` 0, the SDK's
    /// default: the acceleration follows `vel`). Returns the ticket to wait on.
    pub fn move_j(
        &mut self,
        now: f64,
        target: Joints,
        vel: f64,
        acc: f64,
        ovl: f64,
    ) -> Result<u64, i32> {
        if let Some(code) = self.motion_refusal() {
            return Err(code);
        }
        let in_range = |v: f64| v.is_finite() && v > 0.0 && v <= 100.0;
        let acc_ok = acc == 0.0 || in_range(acc);
        if !self.within_limits(&target) || !in_range(vel) || !acc_ok || !in_range(ovl) {
            return Err(codes::PARAM_VALUE);
        }
        if self.servo_session {
            return Err(codes::EXECUTION_FAILED);
        }
        let ticket = self.next_ticket;
        self.next_ticket += 1;
        let overall = ovl / 100.0 * self.speed_percent / 100.0;
        let acc = if acc == 0.0 { vel } else { acc };
        self.queue.push_back(QueuedMove {
            ticket,
            target,
            speed_scale: vel / 100.0 * overall,
            acc_scale: acc / 100.0 * overall,
        });
        if self.active.is_none() {
            self.start_next(now);
        }
        self.motion_commands += 1;
        Ok(ticket)
    }

    fn start_next(&mut self, now: f64) {
        self.advance(now);
        self.begin_next(now);
    }

    /// Starts the next queued move from the set point, unless the arm is braking.
    fn begin_next(&mut self, now: f64) {
        if self.brake.is_some() {
            return;
        }
        self.servo_step = None;
        if let Some(next) = self.queue.pop_front() {
            let speed = self.config.max_speed_deg.map(|v| v * next.speed_scale);
            let acc = self.config.max_acc_deg.map(|v| v * next.acc_scale);
            self.active = Some(ActiveMove {
                ticket: next.ticket,
                profile: Profile::new(self.setpoint, next.target, now, &speed, &acc),
            });
        }
    }

    /// `ServoMoveStart()`.
    pub fn servo_start(&mut self) -> i32 {
        if let Some(code) = self.motion_refusal() {
            return code;
        }
        if self.active.is_some() || !self.queue.is_empty() || self.brake.is_some() {
            return codes::EXECUTION_FAILED;
        }
        self.servo_session = true;
        self.servo_reference = None;
        codes::OK
    }

    /// `ServoJ(target, …, cmdT, …)`.
    pub fn servo_j(&mut self, now: f64, target: Joints, cmd_t: f64) -> i32 {
        if let Some(code) = self.motion_refusal() {
            return code;
        }
        if !self.servo_session {
            return codes::EXECUTION_FAILED;
        }
        if !(0.001..=0.016).contains(&cmd_t) || !finite(&target) {
            return codes::PARAM_VALUE;
        }
        if let Some(j) = self.outside_limits(&target) {
            self.raise(now, MAIN_CODE_SERVOJ_OVER_LIMIT, j as i32 + 1);
            return codes::SERVOJ_OVER_LIMIT;
        }
        self.advance(now);
        let reference = self.servo_reference.unwrap_or(self.setpoint);
        let tolerance = 1.0 + self.config.servo_speed_tolerance;
        let too_fast = (0..6).find(|&j| {
            (target[j] - reference[j]).abs() > self.config.max_speed_deg[j] * tolerance * cmd_t
        });
        if let Some(j) = too_fast {
            self.raise(now, MAIN_CODE_SERVOJ_OVER_LIMIT, j as i32 + 11);
            return codes::SERVOJ_OVER_LIMIT;
        }
        self.servo_reference = Some(target);
        self.servo_targets.push_back((now, target));
        while self.servo_targets.len() > SERVO_TARGETS_KEPT {
            if let Some((_, old)) = self.servo_targets.pop_front() {
                self.servo_target_before = old;
            }
        }
        self.servo_step = Some(ServoStep {
            from: self.setpoint,
            to: target,
            start: now,
            duration: cmd_t,
        });
        self.motion_commands += 1;
        codes::OK
    }

    /// `ServoMoveEnd()`: the last target is still reached.
    pub fn servo_end(&mut self) -> i32 {
        self.servo_session = false;
        codes::OK
    }

    /// `StopMotion()`.
    pub fn stop_motion(&mut self, now: f64) -> i32 {
        self.abort(now, codes::EXECUTION_FAILED);
        codes::OK
    }

    /// Moves the set point along the motion under way to time `now` (never back: callers'
    /// clocks differ by a physics step).
    fn advance(&mut self, now: f64) {
        let dt = now - self.setpoint_time;
        if dt <= 0.0 {
            return;
        }
        let before = self.setpoint;
        let mut braked = false;
        if let Some(brake) = &self.brake {
            self.setpoint = brake.at(now);
            if brake.finished(now) {
                self.brake = None;
                braked = true;
            }
        } else if let Some(active) = &self.active {
            self.setpoint = active.profile.at(now);
        } else if let Some(step) = &self.servo_step {
            let desired = step.at(now);
            let cap = self
                .config
                .max_speed_deg
                .map(|v| v * self.speed_percent / 100.0);
            self.setpoint = rate_limited(&self.setpoint, &desired, &cap, dt);
        }
        self.velocity = std::array::from_fn(|j| (self.setpoint[j] - before[j]) / dt);
        self.setpoint_time = now;
        if braked {
            self.velocity = [0.0; 6];
            if self.active.is_none() {
                self.begin_next(now);
            }
        }
    }

    /// Whether the arm is commanded to be still: no move queued or under way, not braking,
    /// the last servo target reached by the set point.
    pub fn motion_done(&self) -> bool {
        self.active.is_none()
            && self.queue.is_empty()
            && self.brake.is_none()
            && self.servo_step.as_ref().is_none_or(|s| {
                s.finished(self.setpoint_time) && max_gap(&s.to, &self.setpoint) < 1e-6
            })
    }

    // ── Gripper ────────────────────────────────────────────────────────────

    /// `ActGripper(index, action)`: 1 activates, 0 resets.
    pub fn act_gripper(&mut self, index: i64, action: i64) -> i32 {
        if !(1..=8).contains(&index) {
            return codes::PARAM_VALUE;
        }
        match action {
            0 => {
                self.gripper.active = false;
                self.gripper.done = true;
            }
            1 => self.gripper.active = true,
            _ => return codes::PARAM_VALUE,
        }
        codes::OK
    }

    /// `MoveGripper(index, pos, vel, force, maxtime, …)`: returns the command's number to wait
    /// on when the call blocks.
    pub fn move_gripper(
        &mut self,
        now: f64,
        index: i64,
        percent: [i64; 3],
        max_time_ms: i64,
    ) -> Result<u64, i32> {
        if self.estop {
            return Err(codes::EMERGENCY_STOP);
        }
        if self.safety.iter().any(|&s| s) {
            return Err(codes::SAFETY_STOP);
        }
        if !(1..=8).contains(&index)
            || percent.iter().any(|p| !(0..=100).contains(p))
            || !(0..=30_000).contains(&max_time_ms)
        {
            return Err(codes::PARAM_VALUE);
        }
        if !self.gripper.active {
            return Err(codes::GRIPPER_MOTION);
        }
        let max_time = if max_time_ms == 0 {
            30.0
        } else {
            max_time_ms as f64 / 1000.0
        };
        self.motion_commands += 1;
        Ok(self
            .gripper
            .command(now, percent.map(|p| p as f64), max_time))
    }

    /// Whether gripper command `command` is still moving.
    pub fn gripper_moving(&self, command: u64) -> bool {
        self.gripper.command == command && !self.gripper.done
    }

    /// `GetGripperMotionDone()`: `(fault, status)`, status 1 when done.
    pub fn gripper_motion_done(&self) -> (i32, i32) {
        (0, self.gripper.done as i32)
    }

    // ── Kinematics ─────────────────────────────────────────────────────────

    /// `GetForwardKin(joints)`: the TCP pose on the wire.
    pub fn forward_kin(&self, q_deg: &Joints) -> Result<[f64; 6], i32> {
        if !finite(q_deg) {
            return Err(codes::PARAM_VALUE);
        }
        let q: Vec<f64> = q_deg.iter().map(|v| v.to_radians()).collect();
        Ok(pose_to_wire(&self.chain.forward(&q)))
    }

    /// `GetInverseKin(0, pose, -1)`: the joints nearest the current ones that reach `pose`.
    pub fn inverse_kin(&self, pose: &[f64; 6]) -> Result<Joints, i32> {
        if !finite(pose) {
            return Err(codes::PARAM_VALUE);
        }
        let seed: Vec<f64> = self
            .measured
            .joints_deg
            .iter()
            .map(|v| v.to_radians())
            .collect();
        let q = self
            .chain
            .inverse(&wire_to_pose(pose), &seed, 1e-5)
            .map_err(|_| codes::IK_FAILED)?;
        let mut out = [0.0; 6];
        for (o, v) in out.iter_mut().zip(&q) {
            *o = v.to_degrees();
        }
        Ok(out)
    }

    // ── The simulation's side ──────────────────────────────────────────────

    /// The set points the drives command at time `now` (the controller's set point through
    /// the drives' tracking).
    pub fn setpoint(&mut self, now: f64) -> Setpoint {
        self.advance(now);
        let joints_deg = self.drives.follow(
            &self.config.tracking,
            self.setpoint_time,
            self.setpoint,
            now,
        );
        Setpoint {
            joints_deg,
            gripper_percent: self.gripper.setpoint(now),
            gripper_force_percent: self.gripper.force_percent,
        }
    }

    /// The controller's own set point (before the drives' tracking).
    pub fn command(&self) -> Joints {
        self.setpoint
    }

    /// How the drives follow their set points now.
    pub fn tracking(&self) -> TrackingModel {
        self.config.tracking
    }

    /// Sets how the drives follow their set points.
    pub fn set_tracking(&mut self, tracking: TrackingModel) {
        self.config.tracking = tracking;
    }

    /// Sets the following-error limit (deg); `None`: not checked.
    pub fn set_following_error(&mut self, limit_deg: Option<f64>) {
        self.config.following_error_deg = limit_deg;
    }

    /// Sets how far a ServoJ step may exceed the top speed, as a share of it.
    pub fn set_servo_speed_tolerance(&mut self, share: f64) {
        self.config.servo_speed_tolerance = share;
    }

    /// Sets the braking deceleration (deg/s²).
    pub fn set_brake_decel(&mut self, deg_s2: f64) {
        self.config.brake_decel_deg_s2 = deg_s2;
    }

    /// Sets the collision level (N of net external force); `None`: detection off.
    pub fn set_collision_level(&mut self, newtons: Option<f64>) {
        self.config.collision_level_n = newtons;
    }

    /// Tracking, following-error limit, ServoJ tolerance, braking and the collision level back
    /// to their defaults.
    pub fn restore_drive_defaults(&mut self) {
        self.config.tracking = TrackingModel::default();
        self.config.following_error_deg = Some(DEFAULT_FOLLOWING_ERROR_DEG);
        self.config.servo_speed_tolerance = DEFAULT_SERVO_SPEED_TOLERANCE;
        self.config.brake_decel_deg_s2 = DEFAULT_BRAKE_DECEL_DEG_S2;
        self.config.collision_level_n = Some(DEFAULT_COLLISION_LEVEL_N);
    }

    /// Feeds what the simulation measured at `now`; ends moves that have arrived; a joint too
    /// far from its set point is a following error; a contact force above the collision level
    /// is a collision.
    pub fn observe(&mut self, now: f64, measured: Measured) {
        self.gripper.observe(now, measured.gripper_percent);
        self.measured = measured;
        self.measured_at = now;
        if let Some(level) = self.config.collision_level_n {
            let force = self.measured.contact_force_n;
            if force <= level {
                self.collision_armed = true;
            } else if self.collision_armed && self.fault.is_none() && !self.collision {
                self.set_collision(now, true, self.measured.contact_joint);
            }
        }
        if let Some(limit) = self.config.following_error_deg
            && self.fault.is_none()
            && self.enabled
        {
            let lagging =
                (0..6).find(|&j| (self.setpoint[j] - self.measured.joints_deg[j]).abs() > limit);
            if let Some(j) = lagging {
                self.raise(now, MAIN_CODE_FOLLOWING_ERROR, j as i32 + 1);
            }
        }
        let Some(active) = &self.active else {
            return;
        };
        let end = active.profile.end();
        if now < end {
            return;
        }
        let m = &self.measured;
        let settled = max_gap(&m.joints_deg, &active.profile.to) < 2.0
            && m.joint_speeds_deg.iter().all(|v| v.abs() < 1.0);
        if settled || now >= end + self.config.settle_timeout {
            let ticket = active.ticket;
            self.active = None;
            self.record(ticket, codes::OK);
            self.start_next(now);
        }
    }

    /// Puts the arm at `q_deg` at rest and the gripper open (a new episode): every motion is
    /// aborted (14), faults and settings stay.
    pub fn rehome(&mut self, now: f64, q_deg: Joints) {
        self.abort(now, codes::EXECUTION_FAILED);
        self.brake = None;
        self.setpoint = q_deg;
        self.velocity = [0.0; 6];
        self.drives = Drives::new(q_deg, now);
        self.measured.joints_deg = q_deg;
        self.measured.joint_speeds_deg = [0.0; 6];
        self.gripper.hold_at(100.0);
    }

    /// Motion commands accepted so far (`MoveJ`, `ServoJ`, `MoveGripper`).
    pub fn motion_commands(&self) -> u64 {
        self.motion_commands
    }

    /// The latest measurement.
    pub fn measured(&self) -> &Measured {
        &self.measured
    }

    /// The state the controller reports, with `joints_deg` as the encoders read (the caller may
    /// add noise); the TCP is computed from them.
    pub fn state_with_joints(&self, joints_deg: Joints) -> RobotState {
        let q: Vec<f64> = joints_deg.iter().map(|v| v.to_radians()).collect();
        let (main_code, sub_code) = self.fault.as_ref().map_or((0, 0), |f| (f.main, f.sub));
        let motion_done = self.motion_done();
        RobotState {
            joints_deg,
            joint_speeds_deg: self.measured.joint_speeds_deg,
            tcp: pose_to_wire(&self.chain.forward(&q)),
            robot_state: if motion_done { 1 } else { 2 },
            robot_mode: if self.automatic { 0 } else { 1 },
            main_code,
            sub_code,
            motion_done,
            emergency_stop: self.estop,
            safety_stop: self.safety,
            enabled: self.enabled,
            gripper_position: fairgrasp_env::arm::readings::gripper_percent_of(
                self.gripper.position,
            ),
            gripper_motion_done: self.gripper.done,
            gripper_active: self.gripper.active,
            gripper_fault: 0,
            gripper_current: self.gripper.current_percent().round() as u8,
            collision: self.collision,
            controller_clock_ms: Some((self.measured_at * 1000.0).round() as i64),
            last_servo_target_deg: Some(self.last_servo_target()),
        }
    }

    /// The last ServoJ target accepted by the time of the latest measurement.
    fn last_servo_target(&self) -> Joints {
        (self.servo_targets.iter().rev())
            .find(|(at, _)| *at <= self.measured_at)
            .map_or(self.servo_target_before, |(_, target)| *target)
    }

    /// The state the controller reports.
    pub fn state(&self) -> RobotState {
        self.state_with_joints(self.measured.joints_deg)
    }
}
