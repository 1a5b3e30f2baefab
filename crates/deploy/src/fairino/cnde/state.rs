//! [`RobotState`] to and from a DATA payload: the requested fields packed in request
//! order, little-endian, no padding (fairino-cnde.md §2.4).
//!
//! Fields of [`RobotState`] map to their wire names; every other field is sent as zeros
//! (except `program_state`, sent as 1 "stopped": no controller program runs, and
//! `frame_head` / `data_len`, which carry what their names say) and ignored on reading.

use super::fields::{Layout, Scalar, StateField};
use crate::Result;
use crate::robot::RobotState;

/// The value a state puts in one field.
enum FieldValue<'a> {
    Floats(&'a [f64]),
    Int(i64),
    Ints(Vec<i64>),
    Zero,
}

/// `robot_time`'s seven values (year, month, day, hour, minute, second, millisecond) for a
/// clock in ms since the start of the month; year and month are left 0.
fn clock_fields(ms: i64) -> Vec<i64> {
    let (day, rest) = (ms / 86_400_000, ms % 86_400_000);
    vec![
        0,
        0,
        day + 1,
        rest / 3_600_000,
        rest / 60_000 % 60,
        rest / 1000 % 60,
        rest % 1000,
    ]
}

/// The clock in ms since the start of the month from `robot_time`'s values, or `None` when
/// they are all zero (a controller that does not fill it).
fn clock_ms(values: &[(f64, i64)]) -> Option<i64> {
    let v: Vec<i64> = values.iter().map(|(_, i)| *i).collect();
    if v.len() < 7 || v.iter().all(|&x| x == 0) {
        return None;
    }
    Some((((v[2] - 1).max(0) * 24 + v[3]) * 60 + v[4]) * 60_000 + v[5] * 1000 + v[6])
}

fn value_of<'a>(name: &str, state: &'a RobotState, payload_len: usize) -> FieldValue<'a> {
    use FieldValue::{Floats, Int, Ints, Zero};
    match name {
        "frame_head" => Int(0x5A5A),
        "data_len" => Int(payload_len as i64),
        "program_state" => Int(1),
        "robot_state" => Int(state.robot_state.into()),
        "robot_mode" => Int(state.robot_mode.into()),
        "main_code" => Int(state.main_code.into()),
        "sub_code" => Int(state.sub_code.into()),
        "actual_joint_pos" => Floats(&state.joints_deg),
        // With no tool frame set (tool_id 0) the flange is the TCP.
        "actual_TCP_pos" | "actual_flange_pos" => Floats(&state.tcp),
        "actual_joint_vel" => Floats(&state.joint_speeds_deg),
        "emergency_stop" => Int(state.emergency_stop.into()),
        "motion_done" => Int(state.motion_done.into()),
        "safety_stop0_state" => Int(state.safety_stop[0].into()),
        "safety_stop1_state" => Int(state.safety_stop[1].into()),
        "rbt_enable_state" => Int(state.enabled.into()),
        "gripper_position" => Int(state.gripper_position.into()),
        "gripper_motion_done" => Int(state.gripper_motion_done.into()),
        "gripper_active" => Int(state.gripper_active.into()),
        "gripper_fault" => Int(state.gripper_fault.into()),
        "gripper_current" => Int(state.gripper_current.into()),
        "collision_state" => Int(state.collision.into()),
        "robot_time" => match state.controller_clock_ms {
            Some(ms) => Ints(clock_fields(ms)),
            None => Zero,
        },
        "last_servoJ_target" => match &state.last_servo_target_deg {
            Some(target) => Floats(target),
            None => Zero,
        },
        _ => Zero,
    }
}

fn write_scalar(out: &mut Vec<u8>, scalar: Scalar, value: f64, int: i64) {
    // Casts truncate on purpose: the wire type is the controller's, not ours.
    match scalar {
        Scalar::U8 => out.push(int as u8),
        Scalar::U16 => out.extend_from_slice(&(int as u16).to_le_bytes()),
        Scalar::I32 => out.extend_from_slice(&(int as i32).to_le_bytes()),
        Scalar::U32 => out.extend_from_slice(&(int as u32).to_le_bytes()),
        Scalar::F64 => out.extend_from_slice(&value.to_le_bytes()),
    }
}

fn write_field(out: &mut Vec<u8>, field: &StateField, value: FieldValue) {
    let wire = field.wire;
    for i in 0..wire.count {
        let (float, int) = match &value {
            FieldValue::Floats(values) => {
                let v = values.get(i).copied().unwrap_or(0.0);
                (v, v as i64)
            }
            FieldValue::Int(v) if i == 0 => (*v as f64, *v),
            FieldValue::Ints(v) => {
                let x = v.get(i).copied().unwrap_or(0);
                (x as f64, x)
            }
            _ => (0.0, 0),
        };
        write_scalar(out, wire.scalar, float, int);
    }
}

/// The DATA payload for a validated layout.
pub fn encode_state_with(layout: &Layout, state: &RobotState) -> Vec<u8> {
    let mut out = Vec::with_capacity(layout.payload_len);
    for (field, _) in &layout.fields {
        write_field(
            &mut out,
            field,
            value_of(field.name, state, layout.payload_len),
        );
    }
    out
}

/// The DATA payload for `names`. Names the controller does not know add no bytes
/// (servers refuse them at config time; see [`Layout::new`]).
pub fn encode_state(names: &[String], state: &RobotState) -> Vec<u8> {
    let known: Vec<String> = names
        .iter()
        .filter(|name| super::fields::field(name).is_some())
        .cloned()
        .collect();
    let layout = Layout::new(&known).expect("only known names remain");
    encode_state_with(&layout, state)
}

fn read_scalar(bytes: &[u8], scalar: Scalar) -> (f64, i64) {
    match scalar {
        Scalar::U8 => (f64::from(bytes[0]), i64::from(bytes[0])),
        Scalar::U16 => {
            let v = u16::from_le_bytes([bytes[0], bytes[1]]);
            (f64::from(v), i64::from(v))
        }
        Scalar::I32 => {
            let v = i32::from_le_bytes(bytes[..4].try_into().expect("4 bytes"));
            (f64::from(v), i64::from(v))
        }
        Scalar::U32 => {
            let v = u32::from_le_bytes(bytes[..4].try_into().expect("4 bytes"));
            (f64::from(v), i64::from(v))
        }
        Scalar::F64 => {
            let v = f64::from_le_bytes(bytes[..8].try_into().expect("8 bytes"));
            (v, v as i64)
        }
    }
}

fn read_values(field: &StateField, bytes: &[u8]) -> Vec<(f64, i64)> {
    let size = field.wire.scalar.size();
    (0..field.wire.count)
        .map(|i| read_scalar(&bytes[i * size..], field.wire.scalar))
        .collect()
}

fn store(state: &mut RobotState, name: &str, values: &[(f64, i64)]) {
    let floats = |target: &mut [f64; 6]| {
        for (slot, (v, _)) in target.iter_mut().zip(values) {
            *slot = *v;
        }
    };
    let int = values[0].1;
    match name {
        "robot_state" => state.robot_state = int as u8,
        "robot_mode" => state.robot_mode = int as u8,
        "main_code" => state.main_code = int as i32,
        "sub_code" => state.sub_code = int as i32,
        "actual_joint_pos" => floats(&mut state.joints_deg),
        "actual_TCP_pos" => floats(&mut state.tcp),
        "actual_joint_vel" => floats(&mut state.joint_speeds_deg),
        "emergency_stop" => state.emergency_stop = int != 0,
        "motion_done" => state.motion_done = int != 0,
        "safety_stop0_state" => state.safety_stop[0] = int != 0,
        "safety_stop1_state" => state.safety_stop[1] = int != 0,
        "rbt_enable_state" => state.enabled = int != 0,
        "gripper_position" => state.gripper_position = int as u8,
        "gripper_motion_done" => state.gripper_motion_done = int != 0,
        "gripper_active" => state.gripper_active = int != 0,
        "gripper_fault" => state.gripper_fault = int as i32,
        "gripper_current" => state.gripper_current = int as u8,
        "collision_state" => state.collision = int != 0,
        "robot_time" => state.controller_clock_ms = clock_ms(values),
        "last_servoJ_target" => {
            let mut target = [0.0; 6];
            floats(&mut target);
            state.last_servo_target_deg = Some(target);
        }
        _ => {}
    }
}

/// Updates `state` from a DATA payload laid out as `layout`. Like the vendor SDK, a short
/// payload updates the fields that fit, in order, and stops at the first that does not;
/// extra bytes are ignored. Returns how many fields were read.
pub fn decode_state_into(layout: &Layout, payload: &[u8], state: &mut RobotState) -> usize {
    let mut read = 0;
    for &(field, offset) in &layout.fields {
        let end = offset + field.wire.size();
        let Some(bytes) = payload.get(offset..end) else {
            break;
        };
        store(state, field.name, &read_values(field, bytes));
        read += 1;
    }
    read
}

/// The state in a DATA payload for `names`, starting from [`RobotState::default`] for
/// whatever the payload does not carry (see [`decode_state_into`]). Errors on unknown names.
pub fn decode_state(names: &[String], payload: &[u8]) -> Result<RobotState> {
    let layout = Layout::new(names)?;
    let mut state = RobotState::default();
    decode_state_into(&layout, payload, &mut state);
    Ok(state)
}

#[cfg(test)]
mod tests {
    use super::super::fields::{DEFAULT_PAYLOAD_LEN, default_state_names};
    use super::*;

    fn sample() -> RobotState {
        RobotState {
            joints_deg: [10.0, -90.0, 45.5, 1.0, 2.0, 3.0],
            joint_speeds_deg: [0.5; 6],
            tcp: [400.0, -20.0, 300.0, 180.0, 0.0, 90.0],
            robot_state: 2,
            robot_mode: 1,
            main_code: 7,
            sub_code: -3,
            motion_done: false,
            emergency_stop: true,
            safety_stop: [false, true],
            enabled: false,
            gripper_position: 42,
            gripper_motion_done: false,
            gripper_active: false,
            gripper_fault: 5,
            gripper_current: 37,
            collision: true,
            controller_clock_ms: Some(((2 * 24 + 13) * 3600 + 7 * 60 + 9) * 1000 + 250),
            last_servo_target_deg: Some([11.0, -89.5, 45.0, 1.5, 2.5, 3.5]),
        }
    }

    #[test]
    fn round_trip_default_set() {
        let names = default_state_names();
        let payload = encode_state(&names, &sample());
        assert_eq!(payload.len(), DEFAULT_PAYLOAD_LEN);
        assert_eq!(decode_state(&names, &payload).unwrap(), sample());
    }

    #[test]
    fn documented_bytes() {
        let names = default_state_names();
        let payload = encode_state(&names, &sample());
        assert_eq!(payload[0], 1, "program_state: stopped");
        assert_eq!(payload[1], 2, "robot_state");
        assert_eq!(&payload[2..6], &7i32.to_le_bytes());
        assert_eq!(&payload[11..19], &10.0f64.to_le_bytes());
        assert_eq!(&payload[59..67], &400.0f64.to_le_bytes());
        assert_eq!(payload[562], 1, "emergency_stop");
        assert_eq!(&payload[563..567], &0i32.to_le_bytes(), "motion_done");
        assert_eq!((payload[577], payload[578]), (0, 1), "safety stops");
        assert_eq!(payload[588], 42, "gripper_position");
        assert_eq!(&payload[810..814], &0i32.to_le_bytes(), "rbt_enable_state");
        assert_eq!(
            &payload[1270..1278],
            &11.0f64.to_le_bytes(),
            "last_servoJ_target"
        );
        assert_eq!(&payload[1310..1318], &3.5f64.to_le_bytes());
    }

    #[test]
    fn partial_payload_fills_what_fits() {
        let names: Vec<String> = ["robot_state", "actual_joint_pos", "main_code"]
            .map(String::from)
            .to_vec();
        let full = encode_state(&names, &sample());
        assert_eq!(full.len(), 1 + 48 + 4);
        let state = decode_state(&names, &full[..30]).unwrap();
        assert_eq!(state.robot_state, 2);
        // The joints did not fit: left as they were.
        assert_eq!(state.joints_deg, RobotState::default().joints_deg);
        assert_eq!(state.main_code, 0);
        let mut long = full.clone();
        long.extend_from_slice(&[0xFF; 10]);
        assert_eq!(decode_state(&names, &long).unwrap().main_code, 7);
    }

    #[test]
    fn header_fields_and_unknown_names() {
        let names: Vec<String> = ["frame_head", "data_len", "robot_state"]
            .map(String::from)
            .to_vec();
        let payload = encode_state(&names, &sample());
        assert_eq!(payload, vec![0x5A, 0x5A, 5, 0, 2]);
        let with_unknown = vec!["nonsense".to_string(), "robot_state".to_string()];
        assert_eq!(encode_state(&with_unknown, &sample()), vec![2]);
        assert!(decode_state(&with_unknown, &[2]).is_err());
    }
}
