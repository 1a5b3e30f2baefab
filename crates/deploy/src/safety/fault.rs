//! Why the deployment loop stopped the arm.

use std::fmt;

/// A reason to stop the arm. Its text names the cause and what to look at.
#[derive(Clone, Debug, PartialEq)]
pub enum Fault {
    /// No fresh state from the controller within the deadline.
    StaleState {
        /// Age of the newest state (ms).
        age_ms: f64,
        /// The watchdog's deadline (ms).
        deadline_ms: f64,
    },
    /// State frames arrive, but the controller's clock in them has not moved for this long:
    /// they carry old data.
    FrozenState {
        /// How long the clock has stood still (ms).
        for_ms: f64,
        /// The watchdog's deadline (ms).
        deadline_ms: f64,
    },
    /// The controller reports a collision (`collision_state`).
    Collision,
    /// The newest object pose is older than the deadline.
    StalePose {
        /// Age of the newest pose (ms).
        age_ms: f64,
        /// The pose deadline (ms).
        deadline_ms: f64,
    },
    /// A camera policy's newest images are older than the deadline.
    StaleFrames {
        /// Age of the oldest of the newest frames (ms).
        age_ms: f64,
        /// The frame deadline (ms).
        deadline_ms: f64,
    },
    /// The state stream failed (closed, reset, unreadable).
    StreamFailed(String),
    /// A call to the controller failed or timed out.
    CallFailed {
        /// The call: an XML-RPC method, or the policy (`policy`, `policy action`).
        call: String,
        /// What went wrong.
        message: String,
    },
    /// The controller reports a fault in `main_code` / `sub_code`.
    ControllerFault {
        /// The controller's `main_code`.
        main_code: i32,
        /// The controller's `sub_code`.
        sub_code: i32,
        /// `main_code` in words.
        meaning: String,
    },
    /// The emergency stop is pressed (`emergency_stop`).
    EmergencyStop,
    /// Safety stop input 0 or 1.
    SafetyStop(usize),
    /// The policy gave NaN or an infinite value (or a wrong number of values).
    NonFiniteOutput {
        /// Which value: of the policy's output, or joint of the filter's target.
        index: usize,
        /// The value found.
        value: f32,
    },
    /// Even the strongest allowed braking would take the TCP out of the workspace box, or a
    /// part of the arm to the table or out of the cell.
    WorkspaceExit {
        /// "TCP", or the model's name of the part (a link, a finger).
        part: String,
        /// Where (mm, robot base frame): the TCP, or the centre of the part's covering sphere.
        at_mm: [f64; 3],
        /// What it breaks, in words.
        limit: String,
    },
    /// The measured arm is outside the soft limits or the box, or moving, when the loop starts.
    UnsafeStart(String),
    /// Ctrl-C.
    Interrupted,
}

impl Fault {
    /// A short name for logs and tests.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::StaleState { .. } => "stale_state",
            Self::FrozenState { .. } => "frozen_state",
            Self::Collision => "collision",
            Self::StalePose { .. } => "stale_pose",
            Self::StaleFrames { .. } => "stale_frames",
            Self::StreamFailed(_) => "stream_failed",
            Self::CallFailed { .. } => "call_failed",
            Self::ControllerFault { .. } => "controller_fault",
            Self::EmergencyStop => "emergency_stop",
            Self::SafetyStop(_) => "safety_stop",
            Self::NonFiniteOutput { .. } => "non_finite_output",
            Self::WorkspaceExit { .. } => "workspace_exit",
            Self::UnsafeStart(_) => "unsafe_start",
            Self::Interrupted => "interrupted",
        }
    }
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::StaleState {
                age_ms,
                deadline_ms,
            } => write!(
                f,
                "stale state: the controller's last state is {age_ms:.0} ms old (deadline \
                 {deadline_ms:.0} ms); check the network and the CNDE stream on port 20005"
            ),
            Self::FrozenState {
                for_ms,
                deadline_ms,
            } => write!(
                f,
                "frozen state: frames arrive but the controller's clock (robot_time) in them has \
                 not moved for {for_ms:.0} ms (deadline {deadline_ms:.0} ms): they carry old data"
            ),
            Self::Collision => write!(
                f,
                "collision: the controller detected a collision (collision_state 1); check the \
                 cell, then clear it on the controller"
            ),
            Self::StalePose {
                age_ms,
                deadline_ms,
            } => write!(
                f,
                "stale object pose: the newest is {age_ms:.0} ms old (deadline {deadline_ms:.0} \
                 ms); check the perception (or the twin's pose feed)"
            ),
            Self::StaleFrames {
                age_ms,
                deadline_ms,
            } => write!(
                f,
                "stale camera images: the newest are {age_ms:.0} ms old (deadline \
                 {deadline_ms:.0} ms); check the camera feed (or the twin's)"
            ),
            Self::StreamFailed(m) => write!(f, "state stream failed: {m}"),
            Self::CallFailed { call, message } => write!(f, "call failed: {call}: {message}"),
            Self::ControllerFault {
                main_code,
                sub_code,
                meaning,
            } => write!(
                f,
                "controller fault: main_code {main_code}, sub_code {sub_code} ({meaning}); \
                 clear it on the teach pendant or with ResetAllError"
            ),
            Self::EmergencyStop => write!(f, "emergency stop pressed"),
            Self::SafetyStop(i) => write!(f, "safety stop {i} active"),
            Self::NonFiniteOutput { index, value } => write!(
                f,
                "non-finite policy output: value {index} is {value}; the model or its \
                 observation is broken"
            ),
            Self::WorkspaceExit { limit, .. } => {
                write!(
                    f,
                    "workspace exit: even braking as hard as allowed, {limit}"
                )
            }
            Self::UnsafeStart(m) => write!(f, "unsafe start: {m}"),
            Self::Interrupted => write!(f, "interrupted (Ctrl-C)"),
        }
    }
}
