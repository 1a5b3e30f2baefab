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
use fairgrasp_deploy::runner::{
    AfterSuccess, DeployOptions, Deployment, JsonLog, ModelIo, TwinHost,
};
use fairgrasp_deploy::twin::faults::FaultCommand;
use fairgrasp_deploy::twin::{Twin, TwinConfig};
use fairgrasp_rl::Policy;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
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
    grasps_on_the_twin("deploy_ppo", Servo::XmlRpc, AfterSuccess::PutDown);
}

#[test]
fn the_same_policy_grasps_over_the_real_time_udp_servo_path() {
    grasps_on_the_twin("deploy_ppo", Servo::Udp, AfterSuccess::PutDown);
}

#[test]
fn after_success_the_arm_can_hold_the_object_instead() {
    grasps_on_the_twin("deploy_ppo", Servo::XmlRpc, AfterSuccess::Hold);
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
#[ignore = "the kinematic drive is not a deployment configuration: its policy does not transfer \
            through the deployment loop (7 of 40 deployment-matched at scale 0.5; a fresh one \
            with [readings] is stopped by the workspace box); configs/ppo_deploy.toml trains \
            through the servo model instead"]
fn a_policy_trained_on_the_kinematic_drive_grasps_on_the_pd_twin() {
    // 18 of 20 at speed scale 0.25 with the session-13 loop (docs/simulation.md).
    grasps_on_the_twin("deploy_ppo_kinematic", Servo::XmlRpc, AfterSuccess::PutDown);
}

/// Three episodes at speed scale 0.5: at least two grasps (one miss is allowed for a loaded
/// host or the policy's rare failure), episodes ended by the success rule, the gripper at the
/// speed scale, the servo commands on the path asked for; after the last grasp the object is
/// back on the table with the gripper open, or still lifted in the closed gripper.
fn grasps_on_the_twin(model: &str, servo: Servo, after_success: AfterSuccess) {
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
        after_success,
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
    let resting_z = twin.object_pose().unwrap().position[2];
    // The object's height against the twin's clock, to catch a drop.
    let done = AtomicBool::new(false);
    let (report, heights) = std::thread::scope(|s| {
        let runner = s.spawn(|| {
            let report = deployment.run(&mut host, &mut pose).unwrap();
            done.store(true, Ordering::Relaxed);
            report
        });
        let mut heights = Vec::new();
        while !done.load(Ordering::Relaxed) {
            heights.push((twin.now(), twin.object_pose().unwrap().position[2]));
            std::thread::sleep(Duration::from_millis(2));
        }
        (runner.join().unwrap(), heights)
    });
    assert!(report.fault.is_none(), "{:?}", report.fault);
    // Nothing is let fall: a 20 cm drop lands at 2 m/s. (Each episode's reset moves the
    // object back to the table at once.)
    let resets: Vec<f64> = (twin.calls().iter())
        .filter(|c| c.method == "TwinReset")
        .map(|c| c.t)
        .collect();
    let fastest_fall = (heights.windows(10))
        .filter(|w| {
            !resets
                .iter()
                .any(|t| (w[0].0 - 0.01..=w[9].0 + 0.01).contains(t))
        })
        .map(|w| (w[0].1 - w[9].1) / (w[9].0 - w[0].0).max(1e-3))
        .fold(0.0_f64, f64::max);
    assert!(
        fastest_fall < 1.0,
        "the object fell at {fastest_fall:.2} m/s"
    );
    if report.episodes.last().unwrap().ended_at_success {
        let lift = twin.object_pose().unwrap().position[2] - resting_z;
        let gripper = twin.state().gripper_position;
        match after_success {
            AfterSuccess::PutDown => assert!(
                lift.abs() < 0.005 && gripper >= 90,
                "put down: the object {lift} m above its resting height, the gripper at {gripper} %"
            ),
            AfterSuccess::Hold => assert!(
                lift > 0.02 && gripper < 90,
                "held: the object {lift} m above its resting height, the gripper at {gripper} %"
            ),
        }
    }
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
