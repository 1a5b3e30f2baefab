//! Transfer itself, not a frozen fixture: a deployment policy trained here from a fixed seed
//! with `configs/ppo_deploy.toml`, then deployed through the deployment-matched evaluation
//! (the deployment loop against the simulated controller, drawn reply latencies, encoder
//! noise) and live on the digital twin over the real protocol.
//!
//! A learning run, so it lives with the benchmarks (`bench/transfer`, in the release build)
//! rather than in `scripts/test`; the weights the shipped configs train are pinned in
//! `crates/rl/tests/train.rs`, so a change to what training does fails the suite at once.
//!
//! What is cut to fit a short run, and why it still guards transfer: the shipped config trains
//! an eighth of its episodes at speed scale 0.25 (1.375x the physics of scale 1 alone) and
//! confirms its stop on 400 validation episodes. Here it trains at scale 1 only and confirms
//! on 200 at a 0.93 bound, and is judged at scale 1: every other part of the deployment's
//! path (readings, the servo ramp, the gripper's controller, the estimator, the safety filter,
//! the sender) is the shipped one.

use fairgrasp_deploy::calibration::Calibration;
mod common;

use common::{shared_host_safety, twin_client};
use fairgrasp_deploy::pose_source::StreamedPose;
use fairgrasp_deploy::robot::RobotLink;
use fairgrasp_deploy::runner::{
    AfterSuccess, DeployOptions, Deployment, JsonLog, ModelIo, TwinHost,
};
use fairgrasp_deploy::safety::SafetyConfig;
use fairgrasp_deploy::twin::faults::FaultCommand;
use fairgrasp_deploy::twin::simulated::{SimulatedController, SimulatedSettings};
use fairgrasp_deploy::twin::{Twin, TwinConfig};
use fairgrasp_rl::Policy;
use fairgrasp_rl::train::{HELD_OUT_SEED_BASE, TrainConfig, train};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

const SEED: u64 = 7;

fn shipped_config() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../configs/ppo_deploy.toml")
}

/// `fairgrasp train --config configs/ppo_deploy.toml --seed 7`, cut as the module says; the
/// model it keeps is `dir/best`.
fn train_deployment_policy(dir: &Path) {
    let text = std::fs::read_to_string(shipped_config()).unwrap();
    let overrides = [
        format!("seed={SEED}"),
        "total_timesteps=1000000".into(),
        "checkpoint_freq=0".into(),
        "env.control.speed_scales=[1.0]".into(),
        "eval.confirm_episodes=200".into(),
        "eval.confirm_lower_bound=0.93".into(),
    ];
    let config = TrainConfig::from_toml_str(&text, &overrides).unwrap();
    let summary = train(&config, dir, |_| {}).unwrap();
    eprintln!(
        "deployment training: {} steps in {:.0} s ({:.0} steps/s), best {:?}",
        summary.num_timesteps, summary.seconds, summary.fps, summary.best
    );
    assert!(
        summary.reached_threshold,
        "no stop within {} steps; best evaluation {:?}",
        summary.num_timesteps, summary.best
    );
}

fn deployment(
    link: Box<dyn RobotLink>,
    policy: Policy,
    episodes: u32,
    safety: SafetyConfig,
    after_success: AfterSuccess,
) -> Deployment {
    let io = ModelIo::for_policy(&policy).unwrap();
    let options = DeployOptions {
        live: true,
        episodes,
        safety,
        after_success,
        ..DeployOptions::default()
    };
    Deployment::new(
        link,
        policy,
        Calibration::identity(&io.limits_rad),
        options,
        JsonLog::create(None).unwrap(),
        Arc::new(AtomicBool::new(false)),
    )
    .unwrap()
}

/// Episodes grasped of `episodes` on the simulated controller (`fairgrasp eval --deployment
/// --speed-scale 1`, its default latency and noise), held-out placements.
fn deployment_matched(model: &Path, episodes: u32) -> u32 {
    let policy = Policy::load(model).unwrap();
    let table = fairgrasp_rl::model::env_table(policy.env_config()).unwrap();
    let settings = SimulatedSettings {
        seed: HELD_OUT_SEED_BASE,
        ..SimulatedSettings::default()
    };
    let link = SimulatedController::new(policy.env_id(), &table, settings).unwrap();
    let safety = SafetyConfig {
        speed_scale: 1.0,
        ..SafetyConfig::default()
    };
    // As `fairgrasp eval --deployment`: judged at success, nothing put down.
    let after = AfterSuccess::Hold;
    let mut deployment = deployment(Box::new(link.clone()), policy, episodes, safety, after);
    let report = deployment
        .run(&mut link.host(), &mut link.pose_source())
        .unwrap();
    assert!(report.fault.is_none(), "{:?}", report.fault);
    assert_eq!(report.episodes.len() as u32, episodes);
    (report.episodes.iter())
        .filter(|e| e.success == Some(true))
        .count() as u32
}

/// Episodes grasped of `episodes` live on `fairgrasp twin --latency-ms 10 --joint-noise-deg
/// 0.05`, over XML-RPC, CNDE and the pose feed.
fn on_the_twin(model: &Path, episodes: u32) -> u32 {
    let faults = vec![
        FaultCommand::parse("latency_ms", "10").unwrap(),
        FaultCommand::parse("joint_noise_deg", "0.05").unwrap(),
    ];
    let twin = Twin::spawn(TwinConfig {
        faults,
        seed: HELD_OUT_SEED_BASE,
        ..TwinConfig::ephemeral()
    })
    .unwrap();
    let client = twin_client(&twin);
    let policy = Policy::load(model).unwrap();
    let safety = shared_host_safety(1.0);
    let after = AfterSuccess::PutDown;
    let mut deployment = deployment(Box::new(client), policy, episodes, safety, after);
    let mut host = TwinHost::detect(&twin.rpc_addr().to_string(), 1)
        .unwrap()
        .expect("the twin says it is one");
    let mut pose = StreamedPose::tcp(
        &twin.pose_addr().unwrap().to_string(),
        Duration::from_secs(1),
    )
    .unwrap();
    let report = deployment.run(&mut host, &mut pose).unwrap();
    assert!(report.fault.is_none(), "{:?}", report.fault);
    assert_eq!(report.episodes.len() as u32, episodes);
    (report.episodes.iter())
        .filter(|e| e.success == Some(true))
        .count() as u32
}

#[test]
#[ignore = "a long learning run (3 min of the suite's 23 on an Intel Xeon 2-vCPU host): bench/transfer runs it"]
fn a_policy_trained_for_deployment_grasps_deployment_matched_and_on_the_twin() {
    let dir = tempfile::tempdir().unwrap();
    train_deployment_policy(dir.path());
    let model = dir.path().join("best");
    let grasped = deployment_matched(&model, 100);
    assert!(
        grasped >= 95,
        "{grasped} of 100 deployment-matched episodes grasped"
    );
    // A few live episodes: the twin runs on wall-clock time with real sockets, so its timing
    // is not reproducible; one miss in three is allowed.
    let live = on_the_twin(&model, 3);
    assert!(live >= 2, "{live} of 3 twin episodes grasped");
}
