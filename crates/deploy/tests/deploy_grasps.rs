//! Policies trained through the deployment's motion model grasp on the digital twin — with reply
//! latency, encoder noise and a speed scale below 1 — over the real protocol: the whole road
//! from a trained model to a controller, judged by the twin; episodes end when the loop sees the
//! task's success rule hold, as they did in training. One policy trained on the PD arm drive
//! (`configs/ppo_deploy.toml`), one on the kinematic drive (`configs/ppo_deploy_kinematic.toml`),
//! which meets the twin's PD arm for the first time here.
//!
//! Its own test binary, and the tests take turns, so no other twin competes with one for the
//! CPU (the twin runs its physics in real time).

use fairgrasp_deploy::calibration::Calibration;
mod common;

use common::{shared_host_safety, twin_client, twin_client_with};
use fairgrasp_deploy::pose_source::StreamedPose;
use fairgrasp_deploy::runner::{DeployOptions, Deployment, JsonLog, ModelIo, TwinHost};
use fairgrasp_deploy::twin::faults::FaultCommand;
use fairgrasp_deploy::twin::{Twin, TwinConfig};
use fairgrasp_rl::policies::Policy;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// One twin at a time.
static TWIN: Mutex<()> = Mutex::new(());

/// A best model under `tests/data/`, from `fairgrasp train --config configs/<name>.toml`
/// (seed 42).
fn model_dir(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

#[test]
fn a_policy_trained_through_the_servo_model_grasps_on_the_twin() {
    // `configs/ppo_deploy.toml`, seed 42 (with [readings]): 39 of 40 at scale 0.5, 38 of 40 at
    // 0.25 and 40 of 40 at 1 on the deployment-matched evaluation.
    grasps_on_the_twin("deploy_ppo", Servo::XmlRpc);
}

#[test]
fn the_same_policy_grasps_over_the_real_time_udp_servo_path() {
    grasps_on_the_twin("deploy_ppo", Servo::Udp);
}

/// How the servo commands travel.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Servo {
    /// XML-RPC calls, each waiting for its reply.
    XmlRpc,
    /// UDP datagrams (`cmdType = 1`), no reply.
    Udp,
}

#[test]
#[ignore = "the kinematic-drive policy does not transfer through the session-15 deployment loop \
            (7 of 40 on the deployment-matched evaluation at scale 0.5; a fresh one with \
            [readings] is stopped by the workspace box): open in the transfer issue"]
fn a_policy_trained_on_the_kinematic_drive_grasps_on_the_pd_twin() {
    // 18 of 20 at speed scale 0.25 with the session-13 loop (docs/simulation.md).
    grasps_on_the_twin("deploy_ppo_kinematic", Servo::XmlRpc);
}

/// Three episodes at speed scale 0.5: at least two grasps (one miss is allowed for a loaded
/// host or the policy's rare failure), episodes ended by the success rule, the gripper at the
/// speed scale, the servo commands on the path asked for.
fn grasps_on_the_twin(model: &str, servo: Servo) {
    let _turn = TWIN.lock().unwrap_or_else(|e| e.into_inner());
    let faults = ["latency_ms=10", "joint_noise_deg=0.05"]
        .iter()
        .map(|f| FaultCommand::parse_assignment(f).unwrap())
        .collect();
    let twin = Twin::spawn(TwinConfig {
        faults,
        ..TwinConfig::ephemeral()
    })
    .unwrap();
    let client = match servo {
        Servo::XmlRpc => twin_client(&twin),
        Servo::Udp => twin_client_with(&twin, |c| {
            c.servo_udp_port = Some(twin.servo_udp_addr().unwrap().port())
        }),
    };
    let policy = Policy::load(&model_dir(model)).unwrap();
    let io = ModelIo::for_policy(&policy).unwrap();
    let calibration = Calibration::identity(&io.limits_rad);
    let options = DeployOptions {
        live: true,
        episodes: 3,
        safety: shared_host_safety(0.5),
        ..DeployOptions::default()
    };
    let mut deployment = Deployment::new(
        Box::new(client),
        policy,
        calibration,
        options,
        JsonLog::create(None).unwrap(),
        Arc::new(AtomicBool::new(false)),
    )
    .unwrap();
    assert_eq!(deployment.motion_mismatch(), None);
    assert_eq!(
        deployment.servo_ticks(),
        9,
        "1/30 s ÷ 0.5 in periods of at most 8 ms"
    );
    let mut host = TwinHost::detect(&twin.rpc_addr().to_string(), 2_000_000_000)
        .unwrap()
        .expect("the twin says it is one");
    let mut pose = StreamedPose::tcp(
        &twin.pose_addr().unwrap().to_string(),
        Duration::from_secs(1),
    )
    .unwrap();
    let report = deployment.run(&mut host, &mut pose).unwrap();
    assert!(report.fault.is_none(), "{:?}", report.fault);
    let grasped = report
        .episodes
        .iter()
        .filter(|e| e.success == Some(true))
        .count();
    assert!(
        grasped >= 2,
        "{model}: {grasped} of 3 grasps: {:?}",
        report.episodes
    );
    // As in training, an episode ends once the loop has seen the success rule hold on its
    // estimated state (the grasps took 31–46 of the 100 steps on the twin); and the loop never
    // ends one the twin did not judge a grasp.
    for e in &report.episodes {
        if e.ended_at_success {
            assert_eq!(e.success, Some(true), "{e:?}");
            assert!(e.steps < 100, "{e:?}");
        }
    }
    let ended = report.episodes.iter().filter(|e| e.ended_at_success);
    assert!(ended.count() >= 2, "{:?}", report.episodes);
    // The gripper moves at the speed scale, as the arm does: MoveGripper's vel is 50 %.
    let speeds: Vec<_> = twin
        .calls()
        .iter()
        .filter(|c| c.method == "MoveGripper")
        .map(|c| c.params[2].clone())
        .collect();
    assert!(!speeds.is_empty());
    assert!(
        speeds.iter().all(|v| v == &serde_json::json!(50)),
        "{speeds:?}"
    );
    let count = |method: &str| twin.calls().iter().filter(|c| c.method == method).count();
    let (rpc, udp) = (count("ServoJ"), count("udp:ServoJ"));
    match servo {
        Servo::XmlRpc => assert!(rpc > 100 && udp == 0, "{rpc} XML-RPC, {udp} UDP"),
        Servo::Udp => {
            assert!(udp > 100 && rpc == 0, "{rpc} XML-RPC, {udp} UDP");
            assert_eq!(count("udp:ServoMoveStart"), count("udp:ServoMoveEnd"));
            assert_eq!(twin.udp_rejected(), 0);
        }
    }
}
