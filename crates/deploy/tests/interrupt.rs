//! Ctrl-C in every phase of a live run on the twin — the blocking MoveJ home, the servo
//! stream, a gripper command under way, the operator's prompt — reaches the controller as a
//! StopMotion within 100 ms, and the arm comes to rest as fast as braking allows: judged from
//! the twin's own records (its call log, and joint speeds stamped with its controller clock).
//! No arm stops dead: the twin brakes its set point at 720 deg/s² (62 ms from 45 deg/s) and
//! its joints settle after it (`common::DRIVE_SETTLE_S`).

mod common;

use common::{check_came_to_rest, shared_host_safety, twin_client, until_rest};
use fairgrasp_deploy::calibration::Calibration;
use fairgrasp_deploy::fairino::FairinoClient;
use fairgrasp_deploy::pose_source::StreamedPose;
use fairgrasp_deploy::robot::{RobotCommand, RobotLink};
use fairgrasp_deploy::runner::{
    DeployOptions, Deployment, EpisodeHost, JsonLog, ModelIo, OperatorHost, RunReport, TwinHost,
};
use fairgrasp_deploy::twin::{Twin, TwinConfig, TwinHandle};
use fairgrasp_rl::Policy;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// A joint faster than this (deg/s) counts as moving: the fixture policy's servo motion peaks
/// near 9 deg/s at speed scale 1.
const MOVING_DEG_S: f64 = 3.0;

fn model_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../rl/tests/data/format1/ppo")
}

fn deployment(twin: &TwinHandle, speed_scale: f64, interrupt: Arc<AtomicBool>) -> Deployment {
    let policy = Policy::load(&model_dir()).unwrap();
    let calibration = Calibration::identity(&ModelIo::for_policy(&policy).unwrap().limits_rad);
    let options = DeployOptions {
        live: true,
        episodes: 2,
        max_steps: Some(60),
        safety: shared_host_safety(speed_scale),
        ..DeployOptions::default()
    };
    Deployment::new(
        Box::new(twin_client(twin)),
        policy,
        calibration,
        options,
        JsonLog::create(None).unwrap(),
        interrupt,
    )
    .unwrap()
}

fn fastest(twin: &TwinHandle) -> f64 {
    (twin.state().joint_speeds_deg.iter()).fold(0.0, |m, v| m.max(v.abs()))
}

fn moving(twin: &TwinHandle) -> bool {
    fastest(twin) > MOVING_DEG_S
}

/// Runs two episodes on a fresh twin (or waits at an operator's prompt nobody answers),
/// raises the interrupt once `when` holds, and returns the report, the controller time of the
/// interrupt, and what [`until_rest`] saw after it.
fn interrupt_when(
    twin: &TwinHandle,
    speed_scale: f64,
    host: Host,
    when: impl Fn(&TwinHandle) -> bool + Sync,
) -> (RunReport, f64, f64, f64) {
    let interrupt = Arc::new(AtomicBool::new(false));
    let mut deployment = deployment(twin, speed_scale, interrupt.clone());
    let twin_host = || {
        TwinHost::detect(&twin.rpc_addr().to_string(), 1)
            .unwrap()
            .expect("the twin says it is one")
    };
    let mut host: Box<dyn EpisodeHost + Send> = match host {
        Host::Twin => Box::new(twin_host()),
        Host::TwinArmAway => Box::new(ArmAway {
            twin: twin_host(),
            client: twin_client(twin),
        }),
        Host::Operator => Box::new(OperatorHost::new(
            std::io::BufReader::new(Silent),
            interrupt.clone(),
        )),
    };
    let mut pose = StreamedPose::tcp(
        &twin.pose_addr().unwrap().to_string(),
        Duration::from_secs(1),
    )
    .unwrap();
    std::thread::scope(|s| {
        let runner = s.spawn(|| deployment.run(host.as_mut(), &mut pose).unwrap());
        let until = Instant::now() + Duration::from_secs(30);
        while !when(twin) {
            assert!(Instant::now() < until, "the phase never came");
            assert!(
                !runner.is_finished(),
                "the run ended before the phase: {:?}",
                runner.join().unwrap()
            );
            std::thread::sleep(Duration::from_millis(1));
        }
        let raised = twin.now();
        interrupt.store(true, Ordering::Relaxed);
        let (fastest, rest) = until_rest(twin);
        (runner.join().unwrap(), raised, fastest, rest)
    })
}

fn check(report: &RunReport, twin: &TwinHandle, raised: f64, fastest: f64, rest: f64) {
    let fault = report.fault.as_ref().expect("Ctrl-C must stop the run");
    assert_eq!(fault.kind(), "interrupted", "{fault}");
    check_came_to_rest(twin, raised, 0.1, fastest, rest);
    let calls = twin.calls();
    let stop = (calls.iter())
        .position(|c| c.method == "StopMotion")
        .expect("StopMotion reached the twin");
    let moving = ["ServoJ", "MoveJ", "MoveL", "MoveGripper", "ServoMoveStart"];
    let after: Vec<_> = (calls[stop..].iter())
        .filter(|c| moving.contains(&c.method.as_str()) && c.reply == serde_json::json!(0))
        .map(|c| c.method.clone())
        .collect();
    assert!(after.is_empty(), "accepted after the stop: {after:?}");
}

enum Host {
    Twin,
    /// The twin, with the arm moved away from home after each reset, so that the run's MoveJ
    /// home takes a while.
    TwinArmAway,
    /// An operator's prompt nobody answers.
    Operator,
}

struct ArmAway {
    twin: TwinHost,
    client: FairinoClient,
}

impl EpisodeHost for ArmAway {
    fn begin(&mut self, index: u32) -> fairgrasp_deploy::Result<()> {
        self.twin.begin(index)?;
        let mut joints = self.client.latest_state()?.state.joints_deg;
        joints[0] += 40.0;
        self.client.send(&RobotCommand::MoveJ {
            joints_deg: joints,
            speed_percent: 100.0,
            acc_percent: 100.0,
        })
    }

    fn outcome(&mut self) -> fairgrasp_deploy::Result<Option<bool>> {
        self.twin.outcome()
    }
}

#[test]
fn ctrl_c_during_the_move_home_stops_the_arm_within_100_ms() {
    let twin = Twin::spawn(TwinConfig::ephemeral()).unwrap();
    // The run's MoveJ home turns joint 1 back at the speed cap of scale 0.25; the host's
    // MoveJ away turned it forward. (The twin logs a call once answered, so the log cannot
    // tell a MoveJ under way.)
    let (report, raised, fastest, rest) = interrupt_when(&twin, 0.25, Host::TwinArmAway, |t| {
        t.state().joint_speeds_deg[0] < -15.0
    });
    check(&report, &twin, raised, fastest, rest);
    assert!(report.episodes.is_empty());
}

#[test]
fn ctrl_c_while_streaming_stops_the_arm_within_100_ms() {
    let twin = Twin::spawn(TwinConfig::ephemeral()).unwrap();
    let (report, raised, fastest, rest) = interrupt_when(&twin, 1.0, Host::Twin, |t| {
        t.calls().iter().filter(|c| c.method == "ServoJ").count() > 5 && moving(t)
    });
    check(&report, &twin, raised, fastest, rest);
}

#[test]
fn ctrl_c_while_the_gripper_moves_stops_the_arm_within_100_ms() {
    let twin = Twin::spawn(TwinConfig::ephemeral()).unwrap();
    let (report, raised, fastest, rest) = interrupt_when(&twin, 1.0, Host::Twin, |t| {
        let calls = t.calls();
        let servo = calls.iter().position(|c| c.method == "ServoMoveStart");
        servo.is_some_and(|i| calls[i..].iter().any(|c| c.method == "MoveGripper"))
            && !t.state().gripper_motion_done
    });
    check(&report, &twin, raised, fastest, rest);
}

/// An input nobody types at.
struct Silent;

impl std::io::Read for Silent {
    fn read(&mut self, _: &mut [u8]) -> std::io::Result<usize> {
        std::thread::sleep(Duration::from_secs(3600));
        Ok(0)
    }
}

#[test]
fn ctrl_c_at_the_operators_prompt_ends_the_run_and_stops_the_arm() {
    let twin = Twin::spawn(TwinConfig::ephemeral()).unwrap();
    let started = Instant::now();
    let (report, raised, fastest, rest) = interrupt_when(&twin, 1.0, Host::Operator, |_| {
        started.elapsed() > Duration::from_millis(300)
    });
    check(&report, &twin, raised, fastest, rest);
    assert!(report.episodes.is_empty());
}
