//! What the deployment loop needs from a robot controller, whatever carries it: the FAIRINO
//! client over the network ([`crate::fairino`]), the digital twin, or a recording stub in tests.
//!
//! Everything here is in the controller's units (degrees, millimetres), as on the wire.

use crate::Result;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::time::Instant;

/// One state report of the controller (a CNDE frame, decoded).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RobotState {
    /// Joint angles (deg), j1…j6.
    pub joints_deg: [f64; 6],
    /// Joint speeds (deg/s).
    pub joint_speeds_deg: [f64; 6],
    /// TCP pose: x, y, z (mm), rx, ry, rz (deg), in the controller's base frame.
    pub tcp: [f64; 6],
    /// 1 stop, 2 run, 3 pause, 4 drag.
    pub robot_state: u8,
    /// 0 automatic, 1 manual.
    pub robot_mode: u8,
    /// The controller's fault: 0 and 0 when none.
    pub main_code: i32,
    /// Its sub code (`sub_code`).
    pub sub_code: i32,
    /// The arm is in position (no motion under way).
    pub motion_done: bool,
    /// The emergency stop is pressed (`emergency_stop`).
    pub emergency_stop: bool,
    /// Safety stop inputs 0 and 1.
    pub safety_stop: [bool; 2],
    /// The drives are enabled.
    pub enabled: bool,
    /// Gripper position, % of its stroke (0 closed … 100 open).
    pub gripper_position: u8,
    /// The gripper's last motion has ended (`gripper_motion_done`).
    pub gripper_motion_done: bool,
    /// The gripper is activated (`gripper_active`).
    pub gripper_active: bool,
    /// The gripper's fault code, 0 when none (`gripper_fault`).
    pub gripper_fault: i32,
    /// The gripper's current, % of its rating (`gripper_current`): a gripper holding an object
    /// draws the current of its force setting.
    #[serde(default)]
    pub gripper_current: u8,
    /// The controller detected a collision (`collision_state`).
    pub collision: bool,
    /// The controller's clock when it took the state (`robot_time`, ms since the start of the
    /// month), when the stream carries it: a clock that stops while frames keep coming means
    /// they carry old data.
    pub controller_clock_ms: Option<i64>,
    /// The last ServoJ target the controller received (`last_servoJ_target`, deg), when the
    /// stream carries it: it tells when a set point reached the controller, on its clock.
    #[serde(default)]
    pub last_servo_target_deg: Option<[f64; 6]>,
}

impl Default for RobotState {
    fn default() -> Self {
        Self {
            joints_deg: [0.0; 6],
            joint_speeds_deg: [0.0; 6],
            tcp: [0.0; 6],
            robot_state: 1,
            robot_mode: 0,
            main_code: 0,
            sub_code: 0,
            motion_done: true,
            emergency_stop: false,
            safety_stop: [false; 2],
            enabled: true,
            gripper_position: 100,
            gripper_motion_done: true,
            gripper_active: true,
            gripper_fault: 0,
            gripper_current: 0,
            collision: false,
            controller_clock_ms: None,
            last_servo_target_deg: None,
        }
    }
}

/// A state with the moment this process received it.
#[derive(Clone, Debug)]
pub struct StampedState {
    /// The state as received.
    pub state: RobotState,
    /// When this process received it.
    pub received_at: Instant,
    /// Counts received states; a stalled stream stops counting.
    pub sequence: u64,
}

/// A command to the controller: the XML-RPC calls the deployment loop makes, with the
/// controller's own argument conventions (see `fairino-controller.md`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "call")]
pub enum RobotCommand {
    /// Enables or disables the drives.
    RobotEnable {
        /// `true` enables (1), `false` disables (0).
        enable: bool,
    },
    /// 0 automatic, 1 manual.
    Mode {
        /// The mode to switch to.
        mode: u8,
    },
    /// Global speed override, 1–100 %.
    SetSpeed {
        /// The override (%).
        percent: u8,
    },
    /// Blocking joint move; `speed_percent` and `acc_percent` of the controller's maximum
    /// joint speed and acceleration (in (0, 100]).
    MoveJ {
        /// Target joint angles (deg), j1…j6.
        joints_deg: [f64; 6],
        /// Joint speed, % of the maximum (`vel`).
        speed_percent: f64,
        /// Joint acceleration, % of the maximum (`acc`).
        acc_percent: f64,
    },
    /// Starts a servo session: [`RobotCommand::ServoJ`] set points follow.
    ServoMoveStart,
    /// One servo set point, reached in `cmd_t` seconds (0.001–0.016).
    ServoJ {
        /// Set point joint angles (deg), j1…j6.
        joints_deg: [f64; 6],
        /// Time to reach it (s), the controller's `cmdT`.
        cmd_t: f64,
    },
    /// Ends the servo session.
    ServoMoveEnd,
    /// Stops the motion under way.
    StopMotion,
    /// Clears the controller's resettable faults.
    ResetAllError,
    /// Resets or activates a gripper.
    ActGripper {
        /// Gripper number, 1…8.
        index: u8,
        /// `true` activates (1), `false` resets (0).
        activate: bool,
    },
    /// `position_percent`: 0 closed … 100 open; non-blocking.
    MoveGripper {
        /// Gripper number, 1…8.
        index: u8,
        /// Target opening (%).
        position_percent: u8,
        /// Speed, % of the gripper's maximum.
        speed_percent: u8,
        /// Force, % of the gripper's maximum.
        force_percent: u8,
        /// Longest the motion may take (ms).
        max_time_ms: u32,
    },
}

impl RobotCommand {
    /// The XML-RPC method name.
    pub fn method(&self) -> &'static str {
        match self {
            Self::RobotEnable { .. } => "RobotEnable",
            Self::Mode { .. } => "Mode",
            Self::SetSpeed { .. } => "SetSpeed",
            Self::MoveJ { .. } => "MoveJ",
            Self::ServoMoveStart => "ServoMoveStart",
            Self::ServoJ { .. } => "ServoJ",
            Self::ServoMoveEnd => "ServoMoveEnd",
            Self::StopMotion => "StopMotion",
            Self::ResetAllError => "ResetAllError",
            Self::ActGripper { .. } => "ActGripper",
            Self::MoveGripper { .. } => "MoveGripper",
        }
    }

    /// Whether the command can make the arm or the gripper move.
    pub fn moves(&self) -> bool {
        matches!(
            self,
            Self::MoveJ { .. } | Self::ServoJ { .. } | Self::MoveGripper { .. }
        )
    }
}

/// A link to a controller. Implementations put a timeout on every call and never retry on
/// their own: a failed call is an error for the caller (the safety layer stops the arm).
pub trait RobotLink: Send {
    /// The newest state received, or an error when the stream has failed. Does not block.
    fn latest_state(&self) -> Result<StampedState>;

    /// Sends one command and waits for the controller's reply (bounded by the link's
    /// timeout; `MoveJ` blocks until the motion ends, bounded by its own timeout).
    /// A non-zero error code is a [`crate::DeployError::Controller`].
    fn send(&mut self, command: &RobotCommand) -> Result<()>;

    /// The link's clock: real time for a controller; a simulated controller's own time, which
    /// moves only as it is waited on (the deployment-matched evaluation).
    fn now(&self) -> Instant {
        Instant::now()
    }

    /// Waits until `t` on the link's clock.
    fn sleep_until(&mut self, t: Instant) {
        let now = Instant::now();
        if t > now {
            std::thread::sleep(t - now);
        }
    }

    /// A second line to the same controller, usable from another thread while this link's own
    /// call blocks: how a StopMotion reaches the arm during a MoveJ, and how a gripper command
    /// goes out without holding back the servo set points. `None` where calls never block
    /// (a simulated controller, test stubs).
    fn side_line(&self) -> Option<Arc<dyn SideLine>> {
        None
    }
}

/// See [`RobotLink::side_line`]. Each call has the link's timeout.
pub trait SideLine: Send + Sync {
    /// Sends one command and waits for the controller's reply, as [`RobotLink::send`] does.
    fn send(&self, command: &RobotCommand) -> Result<()>;
}
