//! Every CNDE state name with its wire type, and the default set the vendor SDK asks for.
//!
//! The facts are the vendor SDK's state table (`CNDE_STATE_CONFIG` in `Robot.py`, the wire
//! type being the 4th element of each entry), rewritten here as one row per wire name:
//! the three entries whose names contain a comma are two names on the wire, each with its
//! own type (fairino-cnde.md §2.2).

use crate::{DeployError, Result};

/// The scalar types that appear on the wire, all little-endian.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scalar {
    /// Unsigned byte.
    U8,
    /// Unsigned 16-bit integer.
    U16,
    /// Signed 32-bit integer.
    I32,
    /// Unsigned 32-bit integer.
    U32,
    /// Double (f64).
    F64,
}

impl Scalar {
    /// Bytes per value.
    pub const fn size(self) -> usize {
        match self {
            Scalar::U8 => 1,
            Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 => 4,
            Scalar::F64 => 8,
        }
    }
}

/// A wire type: `count` packed values of one scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WireType {
    /// The type of each value.
    pub scalar: Scalar,
    /// How many values (6 for a joint or pose vector).
    pub count: usize,
}

impl WireType {
    /// Bytes on the wire.
    pub const fn size(self) -> usize {
        self.scalar.size() * self.count
    }
}

/// One state variable on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StateField {
    /// The name the client puts in its output config.
    pub name: &'static str,
    /// Its type and size.
    pub wire: WireType,
}

const fn f(name: &'static str, scalar: Scalar, count: usize) -> StateField {
    StateField {
        name,
        wire: WireType { scalar, count },
    }
}

use Scalar::{F64, I32, U8, U16, U32};

/// Every wire name the controller knows, in the vendor table's order.
pub const STATE_FIELDS: &[StateField] = &[
    f("frame_head", U16, 1),
    f("frame_cnt", U8, 1),
    f("data_len", U16, 1),
    f("program_state", U8, 1),
    f("robot_state", U8, 1),
    f("main_code", I32, 1),
    f("sub_code", I32, 1),
    f("robot_mode", U8, 1),
    f("actual_joint_pos", F64, 6),
    f("actual_TCP_pos", F64, 6),
    f("actual_flange_pos", F64, 6),
    f("actual_joint_vel", F64, 6),
    f("actual_joint_acc", F64, 6),
    f("target_TCP_cmpvel", F64, 2),
    f("target_TCP_vel", F64, 6),
    f("actual_TCP_cmpvel", F64, 2),
    f("actual_TCP_vel", F64, 6),
    f("actual_joint_torque", F64, 6),
    f("tool_id", I32, 1),
    f("wobj_id", I32, 1),
    f("cfg_DO_box", U8, 1),
    f("std_DO_box", U8, 1),
    f("cfg_DO_tool", U8, 1),
    f("cfg_DI_box", U8, 1),
    f("std_DI_box", U8, 1),
    f("cfg_DI_tool", U8, 1),
    f("std_AI0_box", F64, 1),
    f("std_AI1_box", F64, 1),
    f("std_AI_tool", F64, 1),
    f("ft_sensor_raw_data", F64, 6),
    f("ft_sensor_data", F64, 6),
    f("ft_sensor_active", U8, 1),
    f("emergency_stop", U8, 1),
    f("motion_done", I32, 1),
    f("gripper_motion_done", U8, 1),
    f("motion_queue_len", I32, 1),
    f("collision_state", U8, 1),
    f("trajectory_pnum", I32, 1),
    f("safety_stop0_state", U8, 1),
    f("safety_stop1_state", U8, 1),
    f("gripper_fault_id", U8, 1),
    f("gripper_fault", I32, 1),
    f("gripper_active", I32, 1),
    f("gripper_position", U8, 1),
    f("gripper_speed", I32, 1),
    f("gripper_current", I32, 1),
    f("gripper_temp", I32, 1),
    f("gripper_voltage", I32, 1),
    f("aux_axis_state", U8, 25),
    f("exaxis_status", U8, 116),
    f("ext_DI_state", U8, 16),
    f("ext_DO_state", U8, 16),
    f("ext_AI_state", I32, 4),
    f("ext_AO_state", I32, 4),
    f("rbt_enable_state", I32, 1),
    f("joint_driver_torque", F64, 6),
    f("actual_joint_temp", F64, 6),
    f("robot_time", I32, 7),
    f("software_upgrade_state", I32, 1),
    f("end_lua_err_code", I32, 1),
    f("std_AO0_box", F64, 1),
    f("std_AO1_box", F64, 1),
    f("std_AO_tool", F64, 1),
    f("rotating_gripper_num", F64, 1),
    f("rotating_gripper_speed", U8, 1),
    f("rotating_gripper_tor", U8, 1),
    f("weld_break_off_state", U8, 1),
    f("weld_arc_state", U8, 1),
    f("target_joint_torque", F64, 6),
    f("smarttool_state", U32, 1),
    f("wide_voltage_ctrl_box_temp", F64, 1),
    f("wide_voltage_ctrl_box_fan_current", I32, 1),
    f("tool_coord", F64, 6),
    f("wobj_coord", F64, 6),
    f("exTool_coord", F64, 6),
    f("exAxis_coord", F64, 6),
    f("payload", F64, 1),
    f("pay_cog", F64, 3),
    f("last_servoJ_target", F64, 6),
    f("servoJ_cmd_num", I32, 1),
    f("target_joint_pos", F64, 6),
    f("target_joint_vel", F64, 6),
    f("target_joint_acc", F64, 6),
    f("target_joint_current", F64, 6),
    f("actual_joint_current", F64, 6),
    f("actual_TCP_force", F64, 6),
    f("target_TCP_pos", F64, 6),
    f("collision_level", U8, 6),
    f("speed_scaling_man", F64, 1),
    f("speed_scaling_auto", F64, 1),
    f("line_number", I32, 1),
    f("abnormal_stop", U8, 1),
    f("cur_lua_file_name", U8, 256),
    f("prog_total_line", U8, 1),
    f("safety_box_signal", U8, 6),
    f("welding_voltage", F64, 1),
    f("welding_current", F64, 1),
    f("welding_track_speed", F64, 1),
    f("tpd_exception", U8, 1),
    f("alarm_reboot_robot", U8, 1),
    f("modbus_master_connect", U8, 1),
    f("modbus_slave_connect", U8, 1),
    f("btn_box_stop_signal", U8, 1),
    f("drag_alarm", U8, 1),
    f("safety_door_alarm", U8, 1),
    f("safety_plane_alarm", U8, 1),
    f("motion_alarm", U8, 1),
    f("interfere_alarm", U8, 1),
    f("udp_cmd_state", I32, 1),
    f("weld_ready_state", U8, 1),
    f("alarm_check_emerg_stop_btn", U8, 1),
    f("ts_tm_cmd_com_error", U8, 1),
    f("ts_tm_state_com_error", U8, 1),
    f("ctrl_box_error", I32, 1),
    f("safety_data_state", U8, 1),
    f("force_sensor_err_state", U8, 1),
    f("ctrl_open_lua_errcode", U8, 4),
    f("strange_pos_flag", U8, 1),
    f("alarm", U8, 1),
    f("dr_alarm", U8, 1),
    f("socket_conn_timeout", U8, 1),
    f("socket_read_timeout", U8, 1),
    f("ts_web_state_com_err", U8, 1),
    f("alive_slave_num_error", U8, 1),
    f("slave_com_error", U8, 8),
    f("cmd_point_error", U8, 1),
    f("IO_error", U8, 1),
    f("gripper_error", U8, 1),
    f("file_error", U8, 1),
    f("para_error", U8, 1),
    f("exaxis_out_slimit_error", U8, 1),
    f("dr_com_err", U8, 6),
    f("dr_err", U8, 1),
    f("out_sflimit_err", U8, 1),
    f("axle_gen_com_data", U8, 130),
    f("check_sum", U16, 1),
];

/// The names the vendor SDK configures by default (its 73 default states, 76 names on the
/// wire), in wire order: a payload of [`DEFAULT_PAYLOAD_LEN`] bytes.
pub const DEFAULT_STATE_NAMES: [&str; 76] = [
    "program_state",
    "robot_state",
    "main_code",
    "sub_code",
    "robot_mode",
    "actual_joint_pos",
    "actual_TCP_pos",
    "actual_flange_pos",
    "actual_joint_vel",
    "actual_joint_acc",
    "target_TCP_cmpvel",
    "target_TCP_vel",
    "actual_TCP_cmpvel",
    "actual_TCP_vel",
    "actual_joint_torque",
    "tool_id",
    "wobj_id",
    "cfg_DO_box",
    "std_DO_box",
    "cfg_DO_tool",
    "cfg_DI_box",
    "std_DI_box",
    "cfg_DI_tool",
    "std_AI0_box",
    "std_AI1_box",
    "std_AI_tool",
    "ft_sensor_raw_data",
    "ft_sensor_data",
    "ft_sensor_active",
    "emergency_stop",
    "motion_done",
    "gripper_motion_done",
    "motion_queue_len",
    "collision_state",
    "trajectory_pnum",
    "safety_stop0_state",
    "safety_stop1_state",
    "gripper_fault_id",
    "gripper_fault",
    "gripper_active",
    "gripper_position",
    "gripper_speed",
    "gripper_current",
    "gripper_temp",
    "gripper_voltage",
    "aux_axis_state",
    "exaxis_status",
    "ext_DI_state",
    "ext_DO_state",
    "ext_AI_state",
    "ext_AO_state",
    "rbt_enable_state",
    "joint_driver_torque",
    "actual_joint_temp",
    "robot_time",
    "software_upgrade_state",
    "end_lua_err_code",
    "std_AO0_box",
    "std_AO1_box",
    "std_AO_tool",
    "rotating_gripper_num",
    "rotating_gripper_speed",
    "rotating_gripper_tor",
    "weld_break_off_state",
    "weld_arc_state",
    "target_joint_torque",
    "smarttool_state",
    "wide_voltage_ctrl_box_temp",
    "wide_voltage_ctrl_box_fan_current",
    "tool_coord",
    "wobj_coord",
    "exTool_coord",
    "exAxis_coord",
    "payload",
    "pay_cog",
    "last_servoJ_target",
];

/// The vendor SDK's default period (ms).
pub const DEFAULT_PERIOD_MS: u16 = 8;
/// The periods the controller accepts (ms).
pub const PERIOD_RANGE_MS: std::ops::RangeInclusive<u16> = 8..=1000;
/// Payload bytes of a DATA frame for [`DEFAULT_STATE_NAMES`].
pub const DEFAULT_PAYLOAD_LEN: usize = 1318;

/// [`DEFAULT_STATE_NAMES`] as owned strings, as the config functions take them.
pub fn default_state_names() -> Vec<String> {
    DEFAULT_STATE_NAMES.iter().map(|s| s.to_string()).collect()
}

/// The field of a wire name, `None` for names the controller does not know.
pub fn field(name: &str) -> Option<&'static StateField> {
    STATE_FIELDS.iter().find(|field| field.name == name)
}

/// Where each requested name sits in a DATA payload, and the payload's length.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Layout {
    /// `(field, offset)` in request order.
    pub fields: Vec<(&'static StateField, usize)>,
    /// Bytes of the whole payload.
    pub payload_len: usize,
}

impl Layout {
    /// The layout of `names`; an error naming the first unknown name.
    pub fn new(names: &[String]) -> Result<Layout> {
        let mut fields = Vec::with_capacity(names.len());
        let mut offset = 0;
        for name in names {
            let field = field(name).ok_or_else(|| {
                DeployError::config("CNDE state name", format!("unknown name `{name}`"))
            })?;
            fields.push((field, offset));
            offset += field.wire.size();
        }
        Ok(Layout {
            fields,
            payload_len: offset,
        })
    }

    /// The offset of `name` in the payload, if requested.
    pub fn offset_of(&self, name: &str) -> Option<usize> {
        self.fields
            .iter()
            .find(|(field, _)| field.name == name)
            .map(|&(_, offset)| offset)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    #[test]
    fn names_are_unique_and_defaults_known() {
        let names: HashSet<_> = STATE_FIELDS.iter().map(|f| f.name).collect();
        assert_eq!(names.len(), STATE_FIELDS.len());
        let defaults: HashSet<_> = DEFAULT_STATE_NAMES.iter().collect();
        assert_eq!(defaults.len(), 76);
        for name in DEFAULT_STATE_NAMES {
            assert!(field(name).is_some(), "{name}");
        }
    }

    #[test]
    fn default_offsets_match_the_reference() {
        let layout = Layout::new(&default_state_names()).unwrap();
        assert_eq!(layout.payload_len, DEFAULT_PAYLOAD_LEN);
        // Offsets from fairino-cnde.md §2.5.
        for (name, offset) in [
            ("program_state", 0),
            ("robot_state", 1),
            ("main_code", 2),
            ("sub_code", 6),
            ("robot_mode", 10),
            ("actual_joint_pos", 11),
            ("actual_TCP_pos", 59),
            ("actual_flange_pos", 107),
            ("actual_joint_vel", 155),
            ("target_TCP_cmpvel", 251),
            ("actual_joint_torque", 379),
            ("tool_id", 427),
            ("cfg_DO_box", 435),
            ("std_AI0_box", 441),
            ("std_AI1_box", 449),
            ("std_AI_tool", 457),
            ("ft_sensor_active", 561),
            ("emergency_stop", 562),
            ("motion_done", 563),
            ("gripper_motion_done", 567),
            ("safety_stop0_state", 577),
            ("safety_stop1_state", 578),
            ("gripper_fault", 580),
            ("gripper_active", 584),
            ("gripper_position", 588),
            ("aux_axis_state", 605),
            ("exaxis_status", 630),
            ("ext_DI_state", 746),
            ("ext_AI_state", 778),
            ("rbt_enable_state", 810),
            ("robot_time", 910),
            ("std_AO0_box", 946),
            ("std_AO_tool", 962),
            ("rotating_gripper_num", 970),
            ("weld_break_off_state", 980),
            ("weld_arc_state", 981),
            ("target_joint_torque", 982),
            ("smarttool_state", 1030),
            ("wide_voltage_ctrl_box_fan_current", 1042),
            ("tool_coord", 1046),
            ("exAxis_coord", 1190),
            ("payload", 1238),
            ("pay_cog", 1246),
            ("last_servoJ_target", 1270),
        ] {
            assert_eq!(layout.offset_of(name), Some(offset), "{name}");
        }
    }

    #[test]
    fn unknown_name_is_named() {
        let names = vec!["robot_state".to_string(), "warp_drive".to_string()];
        let err = Layout::new(&names).unwrap_err().to_string();
        assert!(err.contains("warp_drive"), "{err}");
    }

    #[test]
    fn default_config_payload_is_1158_bytes() {
        let joined = DEFAULT_STATE_NAMES.join(",");
        assert_eq!(joined.len() + 2, 1158);
    }
}
