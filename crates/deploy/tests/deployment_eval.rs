//! The deployment-matched evaluation: the deployment loop — estimator, safety filter, servo
//! schedule, success rule — against the twin's controller model and world in this process, on
//! a simulated clock with drawn reply latencies (`fairgrasp eval --deployment`).

use fairgrasp_deploy::calibration::Calibration;
use fairgrasp_deploy::robot::{RobotCommand, RobotLink};
use fairgrasp_deploy::runner::{AfterSuccess, DeployOptions, Deployment, JsonLog, ModelIo};
use fairgrasp_deploy::safety::SafetyConfig;
use fairgrasp_deploy::twin::evaluation::{Evaluation, evaluate};
use fairgrasp_deploy::twin::simulated::{SimulatedController, SimulatedSettings};
use fairgrasp_rl::Policy;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// `fairgrasp train --config configs/ppo_deploy.toml` (seed 42).
fn model_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/deploy_ppo")
}

fn run(speed_scale: f64, episodes: u32, seed: u64) -> (u32, u32, f64) {
    run_after(speed_scale, episodes, seed, &[])
}

/// [`run`] on a controller that has been sent `before` first (the pendant's settings).
fn run_after(
    speed_scale: f64,
    episodes: u32,
    seed: u64,
    before: &[RobotCommand],
) -> (u32, u32, f64) {
    let policy = Policy::load(&model_dir()).unwrap();
    let io = ModelIo::for_policy(&policy).unwrap();
    let table = fairgrasp_rl::model::env_table(policy.env_config()).unwrap();
    let settings = SimulatedSettings {
        seed,
        ..SimulatedSettings::default()
    };
    let mut link = SimulatedController::new(policy.env_id(), &table, settings).unwrap();
    for command in before {
        link.send(command).unwrap();
    }
    let options = DeployOptions {
        live: true,
        episodes,
        safety: SafetyConfig {
            speed_scale,
            ..SafetyConfig::default()
        },
        ..DeployOptions::default()
    };
    let mut deployment = Deployment::new(
        Box::new(link.clone()),
        policy,
        Calibration::identity(&io.limits_rad),
        options,
        JsonLog::create(None).unwrap(),
        Arc::new(AtomicBool::new(false)),
    )
    .unwrap();
    let report = deployment
        .run(&mut link.host(), &mut link.pose_source())
        .unwrap();
    assert!(report.fault.is_none(), "{:?}", report.fault);
    let grasped = (report.episodes.iter())
        .filter(|e| e.success == Some(true))
        .count() as u32;
    (grasped, report.episodes.len() as u32, link.elapsed())
}

/// `episodes` evaluated at speed scale 1 from held-out seed 2,000,000,200 on a simulated
/// controller that `prepare` sets up first; the evaluation and the controller.
fn evaluate_after(
    episodes: u32,
    prepare: impl FnOnce(&SimulatedController),
    log: Option<&std::path::Path>,
) -> (Evaluation, SimulatedController) {
    let policy = Policy::load(&model_dir()).unwrap();
    let io = ModelIo::for_policy(&policy).unwrap();
    let table = fairgrasp_rl::model::env_table(policy.env_config()).unwrap();
    let link =
        SimulatedController::new(policy.env_id(), &table, SimulatedSettings::default()).unwrap();
    prepare(&link);
    let options = DeployOptions {
        live: true,
        episodes,
        safety: SafetyConfig {
            speed_scale: 1.0,
            ..SafetyConfig::default()
        },
        after_success: AfterSuccess::Hold,
        ..DeployOptions::default()
    };
    let calibration = Calibration::identity(&io.limits_rad);
    let e = evaluate(
        &link,
        &model_dir(),
        &calibration,
        &options,
        2_000_000_200,
        log,
    )
    .unwrap();
    (e, link)
}

/// A fault fails its episode only: the evaluation clears it as an operator would and plays on.
/// The log shows both loops: the faulted one in the file asked for, the next beside it.
#[test]
fn a_fault_fails_its_episode_and_the_evaluation_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("eval.jsonl");
    let (e, _) = evaluate_after(3, |link| link.collide(), Some(&log));
    assert_eq!(e.played, 3, "{e:?}");
    assert_eq!(e.faults.len(), 1, "{e:?}");
    assert!(e.faults[0].contains("collision"), "{e:?}");
    assert!(e.successes >= 1, "{e:?}");
    let records = |name: &str| -> Vec<serde_json::Value> {
        let text = std::fs::read_to_string(dir.path().join(name)).unwrap();
        text.lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect()
    };
    let first = records("eval.jsonl");
    assert!(
        first
            .iter()
            .any(|r| r["fault"].as_str().is_some_and(|f| f.contains("collision"))),
        "the first loop's log names its fault"
    );
    let next = records("eval.2.jsonl");
    let steps = next.iter().filter(|r| r["step"]["obs"].is_array()).count();
    assert!(steps > 0, "the next loop logged its policy steps");
    assert!(next.iter().all(|r| r.get("fault").is_none()));
}

/// The collision level is the simulated controller's to set (`eval --deployment --strict` sets
/// the strict twin's): at 1 N, the touch of a grasp is a collision, and each stops its episode.
#[test]
fn a_controller_set_to_feel_a_touch_stops_every_grasp() {
    let (e, link) = evaluate_after(2, |link| link.set_collision_level(Some(1.0)), None);
    assert_eq!((e.played, e.successes), (2, 0), "{e:?}");
    assert_eq!(e.faults.len(), 2, "{e:?}");
    assert!(e.faults.iter().all(|f| f.contains("collision")), "{e:?}");
    // Stopped on the way, not before it (a still arm feels nothing).
    assert!(link.elapsed() > 0.5, "{} s", link.elapsed());
}

/// A pendant's override of 10 % caps servo motion at 18 deg/s: a stream at full speed would
/// fall behind its set points into a following error. The loop sets the override to its own
/// speed cap's share first.
#[test]
fn the_deployment_sets_the_speed_override_it_streams_at() {
    let slow_pendant = [RobotCommand::SetSpeed { percent: 10 }];
    let (grasped, played, _) = run_after(1.0, 2, 2_000_000_100, &slow_pendant);
    assert_eq!(played, 2);
    assert!(grasped >= 1, "{grasped} of 2");
}

#[test]
fn the_deployment_loop_grasps_on_the_simulated_controller_at_both_speed_scales() {
    // Held-out placements; one miss of five allowed at each scale.
    for scale in [1.0, 0.25] {
        let (grasped, played, seconds) = run(scale, 5, 2_000_000_000);
        assert_eq!(played, 5);
        assert!(grasped >= 4, "{grasped} of 5 at speed scale {scale}");
        // The controller's own time: each episode a MoveJ home and at least ~30 control steps
        // of 1/30 s ÷ the scale.
        assert!(
            seconds > 5.0 / scale,
            "{seconds} s simulated at scale {scale}"
        );
    }
}

#[test]
fn the_simulated_clock_moves_only_when_waited_on() {
    let policy = Policy::load(&model_dir()).unwrap();
    let table = fairgrasp_rl::model::env_table(policy.env_config()).unwrap();
    let mut link =
        SimulatedController::new(policy.env_id(), &table, SimulatedSettings::default()).unwrap();
    let t0 = link.now();
    let s0 = link.latest_state().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    assert_eq!(link.now(), t0, "real time does not move it");
    link.sleep_until(t0 + std::time::Duration::from_millis(100));
    let s1 = link.latest_state().unwrap();
    // A frame every 8 ms: about 12 more in 100 ms, the newest no older than a period and
    // the physics step (4.2 ms) it waited for.
    assert!((11..=13).contains(&(s1.sequence - s0.sequence)), "{s1:?}");
    let age = link.now() - s1.received_at;
    assert!(age <= std::time::Duration::from_millis(13), "{age:?}");
    // A call takes its reply latency (5-15 ms by default).
    let before = link.now();
    link.send(&fairgrasp_deploy::RobotCommand::ResetAllError)
        .unwrap();
    let took = link.now() - before;
    assert!((5..=15).contains(&took.as_millis()), "{took:?}");
}
