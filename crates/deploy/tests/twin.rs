//! The digital twin over loopback, in real time: Python's `xmlrpc.client` with the vendor
//! SDK's argument lists, our own XML-RPC and CNDE clients, every injected fault, episodes and
//! the object-pose feed, and a scripted grasp judged by the task's rule.

use fairgrasp_deploy::fairino::FairinoClient;
use fairgrasp_deploy::fairino::cnde::{CndeClient, default_state_names};
use fairgrasp_deploy::fairino::xmlrpc::{Value, XmlRpcClient};
use fairgrasp_deploy::pose_source::PoseMessage;
use fairgrasp_deploy::twin::controller::{MAIN_CODE_EMERGENCY_STOP, StartState};
use fairgrasp_deploy::twin::faults::FaultCommand;
use fairgrasp_deploy::twin::{Twin, TwinConfig, TwinHandle};
use fairgrasp_deploy::{DeployError, RobotCommand, RobotLink};
use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::process::Command;
use std::time::{Duration, Instant};

mod common;
use common::{DRIVE_SETTLE_S, twin_client, twin_client_with, until_rest};

fn twin() -> TwinHandle {
    Twin::spawn(TwinConfig::ephemeral()).unwrap()
}

fn client(twin: &TwinHandle) -> XmlRpcClient {
    XmlRpcClient::new(&twin.rpc_addr().to_string(), Duration::from_secs(30))
}

fn cnde(twin: &TwinHandle) -> CndeClient {
    CndeClient::connect(
        &twin.cnde_addr().to_string(),
        &default_state_names(),
        8,
        Duration::from_secs(5),
    )
    .unwrap()
}

/// Calls a command and returns its int code.
fn code(c: &XmlRpcClient, method: &str, params: &[Value]) -> i32 {
    match c.call(method, params).unwrap() {
        Value::Int(code) => code,
        other => panic!("{method} answered {other:?}"),
    }
}

/// Calls a getter and returns `[code, numbers…]`.
fn numbers(c: &XmlRpcClient, method: &str, params: &[Value]) -> Vec<f64> {
    match c.call(method, params).unwrap() {
        Value::Array(items) => items.iter().map(|v| v.as_f64().unwrap()).collect(),
        other => panic!("{method} answered {other:?}"),
    }
}

/// The vendor SDK's MoveJ arguments (blocking, `blendT` = -1).
fn move_j(joints: &[f64; 6], vel: f64) -> Vec<Value> {
    vec![
        Value::doubles(joints),
        Value::doubles(&[0.0; 6]),
        Value::Int(0),
        Value::Int(0),
        Value::Double(vel),
        Value::Double(0.0),
        Value::Double(100.0),
        Value::doubles(&[0.0; 4]),
        Value::Double(-1.0),
        Value::Int(0),
        Value::doubles(&[0.0; 6]),
    ]
}

fn move_gripper(pos: i32, block: i32) -> Vec<Value> {
    [1, pos, 100, 50, 3000, block, 0]
        .into_iter()
        .map(Value::Int)
        .chain([Value::Double(0.0), Value::Int(0), Value::Int(0)])
        .collect()
}

fn joints(c: &XmlRpcClient) -> [f64; 6] {
    let v = numbers(c, "GetActualJointPosDegree", &[Value::Int(1)]);
    assert_eq!(v[0], 0.0);
    std::array::from_fn(|j| v[j + 1])
}

/// Polls `check` until it holds or `limit` passes; whether it held.
fn eventually(limit: Duration, mut check: impl FnMut() -> bool) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        if check() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    check()
}

const PYTHON_SCRIPT: &str = r#"
import sys, time, xmlrpc.client
rpc = xmlrpc.client.ServerProxy("http://127.0.0.1:%s" % sys.argv[1])
def check(what, got, want=0):
    if got != want:
        print("FAILED", what, got)
        sys.exit(1)
ip = rpc.GetControllerIP()
check("GetControllerIP", ip[0])
print("ip", ip[1])
q = rpc.GetActualJointPosDegree(1)
check("GetActualJointPosDegree", q[0]); check("joints", len(q), 7)
tcp = rpc.GetActualTCPPose(1)
check("GetActualTCPPose", tcp[0]); check("pose", len(tcp), 7)
target = list(q[1:]); target[0] += 10.0
fk = rpc.GetForwardKin(target)
check("GetForwardKin", fk[0])
start = time.time()
check("MoveJ", rpc.MoveJ(target, fk[1:], 0, 0, 30.0, 0.0, 100.0, [0.0] * 4, -1.0, 0, [0.0] * 6))
print("movej_seconds", time.time() - start)
q = rpc.GetActualJointPosDegree(1)
print("after_movej", q[1])
check("ServoMoveStart", rpc.ServoMoveStart())
servo = list(q[1:])
for i in range(50):
    servo[5] += 0.1
    check("ServoJ", rpc.ServoJ(servo, [0.0] * 4, 0.0, 0.0, 0.008, 0.0, 0.0, 0))
    time.sleep(0.008)
check("ServoMoveEnd", rpc.ServoMoveEnd())
time.sleep(0.3)
print("after_servo", rpc.GetActualJointPosDegree(1)[6] - q[6])
check("ActGripper", rpc.ActGripper(1, 1))
check("MoveGripper", rpc.MoveGripper(1, 30, 50, 50, 5000, 0, 0, 0.0, 0, 0))
done = rpc.GetGripperMotionDone()
check("GetGripperMotionDone", done[0]); check("gripper status", done[2], 1)
print("OK")
"#;

#[test]
fn python_xmlrpc_client_drives_the_twin_with_the_sdk_arguments() {
    if Command::new("python3").arg("--version").output().is_err() {
        println!("python3 not found: skipping the Python xmlrpc.client check");
        return;
    }
    let twin = twin();
    let start_j6 = twin.state().joints_deg[5];
    let out = Command::new("python3")
        .arg("-c")
        .arg(PYTHON_SCRIPT)
        .arg(twin.rpc_addr().port().to_string())
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains("OK"),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let value = |key: &str| -> f64 {
        let line = text.lines().find(|l| l.starts_with(key)).unwrap();
        line.split_whitespace().nth(1).unwrap().parse().unwrap()
    };
    assert!(text.contains("ip 127.0.0.1"), "{text}");
    // 10° at 30 % of 180°/s: about half a second, and the call returned after the motion.
    assert!(value("movej_seconds") > 0.3, "{text}");
    // 50 servo steps of 0.1° on j6: about 5°.
    assert!((value("after_servo") - 5.0).abs() < 1.0, "{text}");
    let state = twin.state();
    assert!(state.gripper_active && state.gripper_position < 40);
    assert!((state.joints_deg[5] - start_j6 - 5.0).abs() < 1.0);
    // Every call is in the log, in order, with its arguments and reply.
    let calls = twin.calls();
    let methods: Vec<&str> = calls.iter().map(|c| c.method.as_str()).collect();
    assert_eq!(
        &methods[..5],
        &[
            "GetControllerIP",
            "GetActualJointPosDegree",
            "GetActualTCPPose",
            "GetForwardKin",
            "MoveJ"
        ]
    );
    let movej = &calls[4];
    assert_eq!(movej.params.len(), 11);
    assert_eq!(movej.params[8], serde_json::json!(-1.0));
    assert_eq!(movej.reply, serde_json::json!(0));
    assert_eq!(methods.iter().filter(|m| **m == "ServoJ").count(), 50);
}

#[test]
fn move_j_blocks_motion_done_goes_0_then_1_and_stop_motion_aborts() {
    let twin = twin();
    let c = client(&twin);
    let stream = cnde(&twin);
    let start = joints(&c);
    let mut target = start;
    target[0] += 15.0;
    let addr = twin.rpc_addr().to_string();
    let mover = std::thread::spawn(move || {
        let c = XmlRpcClient::new(&addr, Duration::from_secs(30));
        let t = Instant::now();
        let code = code(&c, "MoveJ", &move_j(&target, 20.0));
        (code, t.elapsed())
    });
    assert!(
        eventually(Duration::from_secs(5), || !stream
            .latest()
            .unwrap()
            .state
            .motion_done),
        "motion_done went 0"
    );
    let (code_back, took) = mover.join().unwrap();
    assert_eq!(code_back, 0);
    assert!(took > Duration::from_millis(500), "MoveJ blocked: {took:?}");
    assert!(eventually(Duration::from_secs(2), || stream
        .latest()
        .unwrap()
        .state
        .motion_done));
    let arrived = joints(&c);
    assert!((arrived[0] - target[0]).abs() < 1.0, "{arrived:?}");

    // A StopMotion on a second connection ends a blocking MoveJ with a non-zero code.
    let addr = twin.rpc_addr().to_string();
    let mover = std::thread::spawn(move || {
        let c = XmlRpcClient::new(&addr, Duration::from_secs(30));
        code(&c, "MoveJ", &move_j(&start, 5.0))
    });
    assert!(eventually(Duration::from_secs(5), || !twin
        .state()
        .motion_done));
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(code(&c, "StopMotion", &[]), 0);
    assert_eq!(mover.join().unwrap(), 14);
    let stopped = joints(&c);
    assert!(
        (stopped[0] - start[0]).abs() > 5.0,
        "stopped on the way: {stopped:?}"
    );
}

#[test]
fn gating_and_servo_rules_over_xmlrpc() {
    let twin = Twin::spawn(TwinConfig {
        start: StartState {
            enabled: false,
            automatic: false,
            gripper_active: false,
        },
        ..TwinConfig::ephemeral()
    })
    .unwrap();
    let c = client(&twin);
    let q = joints(&c);
    assert_eq!(code(&c, "MoveJ", &move_j(&q, 20.0)), 101, "not enabled");
    assert_eq!(code(&c, "RobotEnable", &[Value::Int(1)]), 0);
    assert_eq!(code(&c, "MoveJ", &move_j(&q, 20.0)), 14, "manual mode");
    assert_eq!(code(&c, "Mode", &[Value::Int(0)]), 0);
    let servo = |q: &[f64; 6]| {
        vec![
            Value::doubles(q),
            Value::doubles(&[0.0; 4]),
            Value::Double(0.0),
            Value::Double(0.0),
            Value::Double(0.008),
            Value::Double(0.0),
            Value::Double(0.0),
            Value::Int(0),
        ]
    };
    assert_eq!(code(&c, "ServoJ", &servo(&q)), 14, "outside a session");
    assert_eq!(code(&c, "ServoMoveStart", &[]), 0);
    let mut over = q;
    over[1] = 500.0;
    assert_eq!(code(&c, "ServoJ", &servo(&over)), 29);
    assert_eq!(
        code(&c, "ServoJ", &servo(&q)),
        14,
        "the error ended the session"
    );
    assert_eq!(code(&c, "ResetAllError", &[]), 0);
    assert!(eventually(Duration::from_secs(5), || code(
        &c,
        "ServoMoveStart",
        &[]
    ) == 0));
    assert_eq!(code(&c, "ServoJ", &servo(&q)), 0);
    assert_eq!(code(&c, "ServoMoveEnd", &[]), 0);
    assert_eq!(
        code(&c, "MoveGripper", &move_gripper(0, 1)),
        73,
        "not activated"
    );
    assert_eq!(code(&c, "ActGripper", &[Value::Int(1), Value::Int(1)]), 0);
    assert_eq!(code(&c, "MoveGripper", &move_gripper(0, 1)), 0);
    assert_eq!(code(&c, "SetSpeed", &[Value::Int(0)]), 4);
    assert_eq!(code(&c, "RobotEnable", &[]), 3, "wrong number of arguments");
    let ik = numbers(
        &c,
        "GetInverseKin",
        &[
            Value::Int(0),
            Value::doubles(&[9000.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
            Value::Int(-1),
        ],
    );
    assert_eq!(ik[0], 28.0);
    let err = c.call("NoSuchMethod", &[]).unwrap_err();
    assert!(err.to_string().contains("NoSuchMethod"), "{err}");
}

#[test]
fn cnde_stream_reports_state_and_injected_faults() {
    let twin = twin();
    let c = client(&twin);
    let stream = cnde(&twin);
    let s = stream.latest().unwrap().state;
    let truth = twin.state();
    for j in 0..6 {
        assert!((s.joints_deg[j] - truth.joints_deg[j]).abs() < 0.5);
    }
    assert!(s.enabled && s.robot_mode == 0 && s.motion_done && s.main_code == 0);

    // An error code appears in main_code/sub_code and stops motion until reset.
    twin.inject(FaultCommand::Error {
        main: 5,
        sub: 2,
        fatal: false,
    });
    assert!(eventually(Duration::from_secs(2), || {
        let s = stream.latest().unwrap().state;
        (s.main_code, s.sub_code) == (5, 2)
    }));
    assert_eq!(code(&c, "MoveJ", &move_j(&joints(&c), 20.0)), 14);
    let err = numbers(&c, "GetRobotErrorCode", &[]);
    assert_eq!(err, vec![0.0, 5.0, 2.0]);
    assert_eq!(code(&c, "ResetAllError", &[]), 0);
    assert!(eventually(Duration::from_secs(2), || stream
        .latest()
        .unwrap()
        .state
        .main_code
        == 0));

    // A stalled stream stops the frames; the connection stays.
    twin.inject(FaultCommand::Stall(true));
    std::thread::sleep(Duration::from_millis(100));
    let before = stream.latest().unwrap().sequence;
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(
        stream.latest().unwrap().sequence,
        before,
        "no frames while stalled"
    );
    twin.inject(FaultCommand::Stall(false));
    assert!(eventually(Duration::from_secs(2), || stream
        .latest()
        .unwrap()
        .sequence
        > before));

    // A reset breaks the client's stream; a new connection works.
    twin.inject(FaultCommand::ResetStream);
    assert!(eventually(Duration::from_secs(2), || stream
        .latest()
        .is_err()));
    assert!(matches!(stream.latest(), Err(DeployError::Network { .. })));
    let again = cnde(&twin);
    assert!(again.latest().is_ok());

    // The e-stop: in the stream, in main_code, and motion refused.
    twin.inject(FaultCommand::Estop(true));
    assert!(eventually(Duration::from_secs(2), || {
        let s = again.latest().unwrap().state;
        s.emergency_stop && (s.main_code, s.sub_code) == MAIN_CODE_EMERGENCY_STOP
    }));
    assert_eq!(code(&c, "MoveJ", &move_j(&joints(&c), 20.0)), 31);
    assert_eq!(code(&c, "ServoMoveStart", &[]), 31);
    twin.inject(FaultCommand::Estop(false));
    assert_eq!(code(&c, "ResetAllError", &[]), 0);

    // A safety stop: its flags in the stream, motion refused with 99.
    twin.inject(FaultCommand::SafetyStop([true, false]));
    assert!(eventually(Duration::from_secs(2), || again
        .latest()
        .unwrap()
        .state
        .safety_stop
        == [true, false]));
    assert_eq!(code(&c, "MoveJ", &move_j(&joints(&c), 20.0)), 99);
    twin.inject(FaultCommand::Clear);
    assert!(eventually(Duration::from_secs(2), || again
        .latest()
        .unwrap()
        .state
        .safety_stop
        == [false, false]));
}

#[test]
fn delays_and_noise_are_measurable() {
    let twin = twin();
    let c = client(&twin);
    let timed = |method: &str| {
        let t = Instant::now();
        c.call(method, &[]).unwrap();
        t.elapsed()
    };
    twin.inject(FaultCommand::LatencyMs(150.0));
    assert!(timed("GetControllerIP") >= Duration::from_millis(150));
    assert!(
        timed("TwinInfo") < Duration::from_millis(150),
        "Twin methods are never delayed"
    );
    twin.inject(FaultCommand::LatencyMs(0.0));
    twin.inject_text("slow", "ResetAllError:300:1").unwrap();
    assert!(timed("GetControllerIP") < Duration::from_millis(300));
    assert!(timed("ResetAllError") >= Duration::from_millis(300));
    assert!(
        timed("ResetAllError") < Duration::from_millis(300),
        "only one call was slowed"
    );

    // Encoder noise: the arm is still, the readings scatter by about the standard deviation.
    let spread = |c: &XmlRpcClient| {
        let reads: Vec<f64> = (0..40).map(|_| joints(c)[0]).collect();
        let mean = reads.iter().sum::<f64>() / reads.len() as f64;
        (reads.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / reads.len() as f64).sqrt()
    };
    assert!(spread(&c) < 0.01);
    twin.inject(FaultCommand::JointNoiseDeg(0.5));
    let noisy = spread(&c);
    assert!((0.25..1.0).contains(&noisy), "{noisy}");

    // Faults from another process: TwinInjectFault.
    let reply = code(
        &c,
        "TwinInjectFault",
        &[Value::from("joint_noise_deg"), Value::Double(0.0)],
    );
    assert_eq!(reply, 0);
    assert_eq!(twin.faults().joint_noise_deg, 0.0);
    assert_eq!(
        code(&c, "TwinInjectFault", &[Value::from("warp"), Value::Int(1)]),
        4
    );
    assert_eq!(
        code(
            &c,
            "TwinInjectFault",
            &[
                Value::from("error"),
                Value::Array(vec![Value::Int(7), Value::Int(1)])
            ]
        ),
        0
    );
    assert_eq!(twin.state().main_code, 7);
}

/// MoveJ above the cube, down, close the gripper, up — all through XML-RPC, the cube's pose
/// from the feed — and the twin judges it a success by the task's rule.
#[test]
fn a_scripted_grasp_over_xmlrpc_succeeds_by_the_tasks_rule() {
    let twin = twin();
    let c = client(&twin);
    let info = c.call("TwinInfo", &[]).unwrap();
    assert_eq!(
        info,
        Value::Array(vec![
            Value::Int(0),
            Value::from("fairgrasp-twin"),
            Value::from("FaArmGrasp-v0")
        ])
    );
    assert_eq!(code(&c, "TwinReset", &[Value::Int(5)]), 0);
    let feed = TcpStream::connect(twin.pose_addr().unwrap()).unwrap();
    feed.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let mut line = String::new();
    BufReader::new(feed).read_line(&mut line).unwrap();
    let cube: PoseMessage = serde_json::from_str(&line).unwrap();
    let [qx, qy, qz, qw] = cube.orientation_xyzw;
    let cube_yaw = (2.0 * (qw * qz + qx * qy))
        .atan2(1.0 - 2.0 * (qy * qy + qz * qz))
        .to_degrees();
    let tcp = numbers(&c, "GetActualTCPPose", &[Value::Int(1)]);
    let yaw = (-4..=4)
        .map(|k| cube_yaw + 90.0 * k as f64)
        .min_by(|a, b| (a - tcp[6]).abs().total_cmp(&(b - tcp[6]).abs()))
        .unwrap();
    let [x, y, z] = cube.position.map(|v| v * 1000.0);
    let ik = |dz: f64| -> [f64; 6] {
        let pose = [x, y, z + dz, 180.0, 0.0, yaw];
        let r = numbers(
            &c,
            "GetInverseKin",
            &[Value::Int(0), Value::doubles(&pose), Value::Int(-1)],
        );
        assert_eq!(r[0], 0.0, "IK of {pose:?}");
        std::array::from_fn(|j| r[j + 1])
    };
    assert_eq!(code(&c, "ActGripper", &[Value::Int(1), Value::Int(1)]), 0);
    assert_eq!(code(&c, "MoveJ", &move_j(&ik(100.0), 60.0)), 0);
    assert_eq!(code(&c, "MoveJ", &move_j(&ik(0.0), 20.0)), 0);
    assert_eq!(code(&c, "MoveGripper", &move_gripper(0, 0)), 0);
    assert_eq!(code(&c, "MoveJ", &move_j(&ik(120.0), 30.0)), 0);
    let result = |c: &XmlRpcClient| numbers(c, "TwinEpisodeResult", &[]);
    assert!(
        eventually(Duration::from_secs(3), || result(&c)[1] == 1.0),
        "{:?}",
        twin.episode()
    );
    let r = result(&c);
    assert!(r[2] > 50.0 && r[4] == 0.0 && r[5] == 1.0, "{r:?}");
    let s = twin.state();
    assert!(!s.collision && s.main_code == 0, "a grasp is no collision");
    assert!(
        s.gripper_current == 50 && s.gripper_motion_done,
        "holding: {s:?}"
    );

    // The next reset counts the episode and places a new cube.
    assert_eq!(code(&c, "TwinReset", &[Value::Int(6)]), 0);
    let tally = twin.tally();
    assert_eq!((tally.episodes, tally.successes), (1, 1));
    assert_eq!(numbers(&c, "TwinTally", &[]), vec![0.0, 1.0, 1.0]);
    assert_eq!(result(&c)[1], 0.0);
    let moved = twin.object_pose().unwrap();
    assert!(
        (moved.position[0] - cube.position[0]).abs() + (moved.position[1] - cube.position[1]).abs()
            > 1e-3
    );
    // An episode where nothing moved is not counted.
    assert_eq!(code(&c, "TwinReset", &[Value::Int(7)]), 0);
    assert_eq!(twin.tally().episodes, 1);
}

/// IK over XML-RPC: joints for `pose`.
fn ik(c: &XmlRpcClient, pose: [f64; 6]) -> [f64; 6] {
    let r = numbers(
        c,
        "GetInverseKin",
        &[Value::Int(0), Value::doubles(&pose), Value::Int(-1)],
    );
    assert_eq!(r[0], 0.0, "IK of {pose:?}");
    std::array::from_fn(|j| r[j + 1])
}

/// A MoveJ that drives the fingertips 60 mm into the table beside the cube: the controller
/// detects the collision, the MoveJ answers 14, the stream shows `collision_state` 1 with the
/// twin's code (201, the joint), the arm brakes to rest within its braking time (the twin's
/// clock), motion is refused until `ResetAllError` clears it. With detection `off` the same
/// press goes unnoticed.
#[test]
fn pressing_the_fingers_into_the_table_is_a_collision_over_xmlrpc() {
    let press = |level: &str| {
        let twin = twin();
        let c = client(&twin);
        let inject = [Value::from("collision_level_n"), Value::from(level)];
        assert_eq!(code(&c, "TwinInjectFault", &inject), 0);
        let cube = twin.object_pose().unwrap();
        let tcp = numbers(&c, "GetActualTCPPose", &[Value::Int(1)]);
        let [x, y, z] = cube.position.map(|v| v * 1000.0);
        let beside = |dz: f64| [x, y + 120.0, z + dz, 180.0, 0.0, tcp[6]];
        assert_eq!(code(&c, "MoveJ", &move_j(&ik(&c, beside(100.0)), 60.0)), 0);
        let answer = code(&c, "MoveJ", &move_j(&ik(&c, beside(-60.0)), 20.0));
        // Watched from the answer on, which comes as the move is stopped.
        let (fastest, rest) = until_rest(&twin);
        (twin, c, answer, fastest, rest)
    };
    let (twin, c, answer, fastest, rest) = press("150");
    assert_eq!(answer, 14, "the press is stopped");
    let stream = cnde(&twin);
    let s = stream.latest().unwrap().state;
    assert!(s.collision, "collision_state in the stream: {s:?}");
    assert_eq!(s.main_code, 201);
    assert!((1..=6).contains(&s.sub_code), "{s:?}");
    let err = numbers(&c, "GetRobotErrorCode", &[]);
    assert_eq!(err[..2], [0.0, 201.0]);
    let since = twin.with_controller(|c| c.collision_since()).unwrap();
    let decel = twin.with_controller(|c| c.config().brake_decel_deg_s2);
    // The press moves at 20 % (36 deg/s at most): braked in 50 ms, settled after.
    let allowed = 36.0 / decel + DRIVE_SETTLE_S;
    assert!(
        rest - since < allowed,
        "at rest {:.0} ms after the collision (fastest seen after {fastest:.1} deg/s)",
        (rest - since) * 1e3
    );
    assert_eq!(code(&c, "MoveJ", &move_j(&joints(&c), 20.0)), 14);
    assert_eq!(code(&c, "ResetAllError", &[]), 0);
    assert!(eventually(Duration::from_secs(2), || {
        let s = stream.latest().unwrap().state;
        !s.collision && s.main_code == 0
    }));

    let (twin, _, answer, _, _) = press("off");
    assert_eq!(answer, 0, "undetected, the press ends");
    assert!(!twin.state().collision && twin.state().main_code == 0);
}

/// A servo session from `from`: 25 ServoJ 8 ms apart, joint 1 up 0.2° each; returns the last
/// set point.
fn stream_joint_1(robot: &mut FairinoClient, from: [f64; 6]) -> [f64; 6] {
    robot.send(&RobotCommand::ServoMoveStart).unwrap();
    let mut q = from;
    for _ in 0..25 {
        q[0] += 0.2;
        robot
            .send(&RobotCommand::ServoJ {
                joints_deg: q,
                cmd_t: 0.008,
            })
            .unwrap();
        std::thread::sleep(Duration::from_millis(8));
    }
    robot.send(&RobotCommand::ServoMoveEnd).unwrap();
    q
}

/// The deploy loop's own client (`FairinoClient`) against the twin.
#[test]
fn fairino_client_commands_the_twin() {
    let twin = twin();
    let mut robot = twin_client(&twin);
    let start = robot.joints_deg().unwrap();
    let mut target = start;
    target[1] += 5.0;
    robot
        .send(&RobotCommand::MoveJ {
            joints_deg: target,
            speed_percent: 30.0,
            acc_percent: 0.0,
        })
        .unwrap();
    assert!((robot.joints_deg().unwrap()[1] - target[1]).abs() < 1.0);
    let q = stream_joint_1(&mut robot, target);
    robot
        .send(&RobotCommand::ActGripper {
            index: 1,
            activate: true,
        })
        .unwrap();
    robot
        .send(&RobotCommand::MoveGripper {
            index: 1,
            position_percent: 50,
            speed_percent: 100,
            force_percent: 50,
            max_time_ms: 3000,
        })
        .unwrap();
    assert!(eventually(Duration::from_secs(3), || {
        let s = robot.latest_state().unwrap().state;
        s.gripper_motion_done
            && (s.gripper_position as i32 - 50).abs() <= 2
            && (s.joints_deg[0] - q[0]).abs() < 0.5
    }));
    twin.inject(FaultCommand::Estop(true));
    let err = robot
        .send(&RobotCommand::MoveJ {
            joints_deg: start,
            speed_percent: 30.0,
            acc_percent: 0.0,
        })
        .unwrap_err();
    assert!(err.to_string().contains("31"), "{err}");
}

/// The real-time path: servo commands as UDP datagrams (`cmdType = 1`) move the twin's arm
/// under the same rules as over XML-RPC; a datagram that is not a servo command moves nothing
/// and is logged with the reason.
#[test]
fn servo_commands_over_udp_move_the_arm_and_bad_datagrams_are_refused() {
    let twin = twin();
    let udp_port = twin.servo_udp_addr().expect("served by default").port();
    let mut robot = twin_client_with(&twin, |c| c.servo_udp_port = Some(udp_port));
    let start = robot.joints_deg().unwrap();
    // Outside a servo session the controller refuses ServoJ (code 14): nothing moves.
    let mut q = start;
    q[0] += 3.0;
    robot
        .send(&RobotCommand::ServoJ {
            joints_deg: q,
            cmd_t: 0.008,
        })
        .unwrap();
    let refused = || {
        twin.calls()
            .iter()
            .any(|c| c.method == "udp:ServoJ" && c.reply == serde_json::json!(14))
    };
    assert!(eventually(Duration::from_secs(2), refused));
    let q = stream_joint_1(&mut robot, start);
    assert!(eventually(Duration::from_secs(2), || {
        (robot.latest_state().unwrap().state.joints_deg[0] - q[0]).abs() < 0.1
    }));
    let methods: Vec<String> = twin.calls().into_iter().map(|c| c.method).collect();
    assert!(!methods.iter().any(|m| m == "ServoJ"), "no XML-RPC servo");
    assert_eq!(methods.iter().filter(|m| *m == "udp:ServoJ").count(), 26);
    // Garbage, a command the port does not serve, a ServoJ with a NaN: none moves the arm.
    let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let nan_j = "ServoJ(30,0,0,0,0,NaN,0,0,0,0,0,0,0.008,0,0,0)";
    for datagram in [
        "hello".to_string(),
        fairgrasp_deploy::fairino::udp::encode(1, 201, "MoveJ()"),
        fairgrasp_deploy::fairino::udp::encode(2, 376, nan_j),
    ] {
        socket
            .send_to(datagram.as_bytes(), ("127.0.0.1", udp_port))
            .unwrap();
    }
    assert!(eventually(Duration::from_secs(2), || twin.udp_rejected() == 3));
    let reasons: Vec<_> = twin
        .calls()
        .into_iter()
        .filter(|c| c.method == "udp")
        .map(|c| c.reply["rejected"].as_str().unwrap_or_default().to_string())
        .collect();
    assert!(reasons[0].contains("framed"), "{reasons:?}");
    assert!(reasons[1].contains("not served"), "{reasons:?}");
    assert!(reasons[2].contains("finite"), "{reasons:?}");
    std::thread::sleep(Duration::from_millis(100));
    let j0 = twin.state().joints_deg[0];
    // Settled where the stream left it (the PD drive's overshoot is ~0.1°), not at 30°.
    assert!((j0 - q[0]).abs() < 0.5, "{j0} vs {}", q[0]);
}

fn servo_j(q: &[f64; 6], cmd_t: f64) -> Vec<Value> {
    vec![
        Value::doubles(q),
        Value::doubles(&[0.0; 4]),
        Value::Double(0.0),
        Value::Double(0.0),
        Value::Double(cmd_t),
        Value::Double(0.0),
        Value::Double(0.0),
        Value::Int(0),
    ]
}

/// A ServoJ step faster than the joint can go is the controller's error 29: the reply says so,
/// the stream shows main_code 29 with the joint, the session ends and the arm brakes to rest
/// near where it was, not at the jump's target.
#[test]
fn a_servo_jump_answers_29_shows_in_the_stream_and_stops_the_arm() {
    let twin = twin();
    let c = client(&twin);
    let stream = cnde(&twin);
    let q = joints(&c);
    assert_eq!(code(&c, "ServoMoveStart", &[]), 0);
    let mut target = q;
    for _ in 0..25 {
        target[0] += 0.4;
        assert_eq!(code(&c, "ServoJ", &servo_j(&target, 0.008)), 0);
        std::thread::sleep(Duration::from_millis(8));
    }
    let mut jump = target;
    jump[0] += 20.0;
    assert_eq!(code(&c, "ServoJ", &servo_j(&jump, 0.008)), 29);
    assert!(
        eventually(Duration::from_secs(5), || {
            let s = stream.latest().unwrap().state;
            (s.main_code, s.sub_code) == (29, 11)
        }),
        "main_code 29, sub_code 11 (j1 too fast) in the stream"
    );
    assert_eq!(code(&c, "ServoJ", &servo_j(&target, 0.008)), 14);
    assert!(eventually(Duration::from_secs(5), || {
        stream.latest().unwrap().state.motion_done
    }));
    let rest = joints(&c);
    // At most 50 deg/s when it stopped: 1.7° of braking at 720 deg/s² past the set point.
    assert!(
        rest[0] < target[0] + 3.0,
        "stopped at {} (last target {}, jump {})",
        rest[0],
        target[0],
        jump[0]
    );
    assert_eq!(code(&c, "ResetAllError", &[]), 0);
    assert!(eventually(Duration::from_secs(5), || {
        stream.latest().unwrap().state.main_code == 0
    }));
    assert_eq!(code(&c, "ServoMoveStart", &[]), 0);
    assert_eq!(code(&c, "ServoMoveEnd", &[]), 0);
}

/// The strict set over XML-RPC: TwinTracking reports the drives' model in force, and the
/// reported joint lags a MoveJ's set point.
#[test]
fn tracking_is_injectable_and_reported() {
    let twin = twin();
    let c = client(&twin);
    assert_eq!(
        numbers(&c, "TwinTracking", &[]),
        [0.0; 13].to_vec(),
        "off by default"
    );
    let inject = |name: &str, value: &str| {
        code(
            &c,
            "TwinInjectFault",
            &[Value::String(name.into()), Value::String(value.into())],
        )
    };
    assert_eq!(inject("tracking", "8,15"), 0);
    assert_eq!(inject("tracking", "8,15,1"), 4, "a bad value is refused");
    let reported = numbers(&c, "TwinTracking", &[]);
    assert_eq!(&reported[..3], &[0.0, 8.0, 15.0]);
    assert_eq!(twin.tracking()[5].tau_ms, 15.0);
    for fault in fairgrasp_deploy::twin::faults::strict() {
        twin.inject(fault);
    }
    let q = joints(&c);
    let mut target = q;
    target[0] += 10.0;
    assert_eq!(code(&c, "MoveJ", &move_j(&target, 30.0)), 0);
    assert!((joints(&c)[0] - target[0]).abs() < 1.0);
    twin.inject(FaultCommand::Clear);
    assert_eq!(numbers(&c, "TwinTracking", &[]), [0.0; 13].to_vec());
}
