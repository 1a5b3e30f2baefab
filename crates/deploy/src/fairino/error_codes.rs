//! Readable meanings of the FAIRINO error codes.
//!
//! Negative codes are produced by the vendor SDKs themselves (communication and file
//! errors; -17…-20 are the Python SDK's CNDE configuration errors), positive ones by the
//! controller. Facts from `fairino-controller.md`, the vendor's `robot_error.h` and its C# SDK's
//! error enum (31, 101).

/// The controller's return codes that fairgrasp names, as the twin gives them and the client
/// reads them ([`error_code_meaning`] has every one the vendor documents).
pub mod codes {
    /// Success.
    pub const OK: i32 = 0;
    /// Wrong number of parameters.
    pub const PARAM_COUNT: i32 = 3;
    /// A parameter out of range.
    pub const PARAM_VALUE: i32 = 4;
    /// Execution failed.
    pub const EXECUTION_FAILED: i32 = 14;
    /// Inverse kinematics failed.
    pub const IK_FAILED: i32 = 28;
    /// A ServoJ target over a joint limit.
    pub const SERVOJ_OVER_LIMIT: i32 = 29;
    /// A fault that cannot be reset: power-cycle the control box.
    pub const NOT_RESETTABLE: i32 = 30;
    /// Emergency stop pressed.
    pub const EMERGENCY_STOP: i32 = 31;
    /// Gripper motion error.
    pub const GRIPPER_MOTION: i32 = 73;
    /// A wait timed out.
    pub const WAIT_TIMEOUT: i32 = 76;
    /// Safety stop (`safety_stop0_state` or `safety_stop1_state` set in the CNDE stream).
    pub const SAFETY_STOP: i32 = 99;
    /// Robot not enabled.
    pub const NOT_ENABLED: i32 = 101;
}

/// What a FAIRINO error code means, in a few words; `"unknown error code"` for any code
/// this table does not know.
pub fn error_code_meaning(code: i64) -> &'static str {
    match code {
        0 => "success",
        -1 => "other SDK error",
        -2 => "network communication failed",
        -3 => "XML-RPC communication failed (check the network and the controller's address)",
        -4 => "XML-RPC call failed, or the SDK is not connected",
        -5 => "Lua file not found",
        -6 => "save path not found",
        -7 => "file to upload not found",
        -8 => "file download failed",
        -9 => "file download check failed",
        -10 => "writing the downloaded file failed",
        -11 => "bad file name",
        -12 => "file upload failed",
        -13 => "file too large",
        -14 => "opening the file failed",
        -15 => "socket send failed",
        -16 => "socket receive failed",
        -17 => "CNDE state configured twice",
        -18 => "CNDE state name not found",
        -19 => "CNDE configuration needs at least one state",
        -20 => "too many CNDE states configured",
        3 => "wrong number of parameters",
        4 => "parameter out of range",
        8 => "file failed to open",
        14 => "execution failed",
        18 => "a program is running",
        25 => "computation failed",
        28 => "inverse kinematics failed",
        29 => "ServoJ joint over limit",
        30 => "fault cannot be reset: power-cycle the control box",
        31 => "emergency stop (once released: power-cycle the control box)",
        33 => "external axis not at zero: lead and resolution not set",
        34 => "wrong workpiece number",
        36 => "file name too long",
        38 => "singular pose",
        41 => "external axis not homed",
        45 => "external axis not active",
        46 => "external axis needs calibration for synchronised motion",
        47 => "external drive configuration failed",
        48 => "reading the external drive configuration timed out",
        52 => "synchronised motion cannot run single-step",
        64 => "command not queued",
        66..=68 => "wrong intermediate point of the circle or spiral",
        69 => "wrong middle point of the arc",
        70 => "wrong target point of the arc",
        73 => "gripper motion error",
        74 => "wrong target point of the line",
        75 => "channel error",
        76 => "wait timed out",
        82 => "wrong TPD command point",
        83 => "wrong TPD tool number",
        94 => "wrong spline point",
        99 => "safety stop",
        101 => "robot not enabled",
        108 => "wrong spiral start point",
        112 => "target pose unreachable",
        130 => "point table not found",
        // Not FAIRINO codes: the twin's main_codes for a following error and a collision
        // (FAIRINO documents none), so a rehearsal's stop names its cause.
        200 => "following error (the fairgrasp twin's main_code)",
        201 => "collision (the fairgrasp twin's main_code; collision_state is set too)",
        _ => "unknown error code",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_and_unknown_codes() {
        assert_eq!(error_code_meaning(14), "execution failed");
        assert_eq!(error_code_meaning(99), "safety stop");
        assert_eq!(error_code_meaning(112), "target pose unreachable");
        assert!(error_code_meaning(-4).contains("not connected"));
        assert_eq!(error_code_meaning(12345), "unknown error code");
        assert_eq!(error_code_meaning(-99), "unknown error code");
    }

    #[test]
    fn every_named_code_has_its_meaning() {
        use codes::*;
        for code in [
            PARAM_COUNT,
            PARAM_VALUE,
            EXECUTION_FAILED,
            IK_FAILED,
            SERVOJ_OVER_LIMIT,
            NOT_RESETTABLE,
            EMERGENCY_STOP,
            GRIPPER_MOTION,
            WAIT_TIMEOUT,
            SAFETY_STOP,
            NOT_ENABLED,
        ] {
            assert_ne!(
                error_code_meaning(code as i64),
                "unknown error code",
                "{code}"
            );
        }
        assert_eq!(error_code_meaning(OK as i64), "success");
    }
}
