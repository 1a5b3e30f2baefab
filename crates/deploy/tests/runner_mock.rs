//! The deployment loop against a stand-in controller whose arm follows every set point at once:
//! the command sequence, dry runs, and each fault stopping the arm with nothing sent after.

use fairgrasp_deploy::calibration::Calibration;
use fairgrasp_deploy::pose_source::{FixedPose, PoseMessage, PoseSource, ReceivedPose};
use fairgrasp_deploy::robot::{RobotCommand, RobotLink, RobotState, StampedState};
use fairgrasp_deploy::runner::{DeployOptions, Deployment, EpisodeHost, JsonLog, ModelIo};
use fairgrasp_deploy::safety::{Fault, SafetyConfig};
use fairgrasp_deploy::{DeployError, Result};
use fairgrasp_rl::Policy;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

fn model_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../rl/tests/data/format1/ppo")
}

/// A policy trained for deployment (`configs/ppo_deploy.toml`): it reaches for the cube.
fn deploy_model_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/deploy_ppo")
}

/// What goes wrong, and when (counted in ServoJ calls received).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Trouble {
    None,
    EStop,
    Stale,
    FaultCode,
    CallError,
    NanJoints,
}

struct Shared {
    state: RobotState,
    sequence: u64,
    received_at: Instant,
    calls: Vec<(Instant, RobotCommand)>,
    servo_calls: usize,
    trouble: Trouble,
    after: usize,
    /// When the fault became visible to the loop.
    fault_at: Option<Instant>,
    /// How long each ServoJ takes to answer.
    servo_reply: Duration,
}

#[derive(Clone)]
struct MockRobot(Arc<Mutex<Shared>>);

impl MockRobot {
    fn new(home: [f64; 6], trouble: Trouble, after: usize) -> Self {
        Self(Arc::new(Mutex::new(Shared {
            state: RobotState {
                joints_deg: home,
                gripper_active: false,
                enabled: false,
                ..RobotState::default()
            },
            sequence: 0,
            received_at: Instant::now(),
            calls: Vec::new(),
            servo_calls: 0,
            trouble,
            after,
            fault_at: None,
            servo_reply: Duration::ZERO,
        })))
    }

    /// Every ServoJ answers `reply` after it is sent.
    fn slow(self, reply: Duration) -> Self {
        self.0.lock().unwrap().servo_reply = reply;
        self
    }

    fn calls(&self) -> Vec<(Instant, RobotCommand)> {
        self.0.lock().unwrap().calls.clone()
    }
}

impl RobotLink for MockRobot {
    fn latest_state(&self) -> Result<StampedState> {
        let mut s = self.0.lock().unwrap();
        let tripped = s.trouble != Trouble::None && s.servo_calls >= s.after;
        if tripped && s.fault_at.is_none() {
            s.fault_at = Some(Instant::now());
        }
        match (tripped, s.trouble) {
            (true, Trouble::EStop) => s.state.emergency_stop = true,
            (true, Trouble::FaultCode) => (s.state.main_code, s.state.sub_code) = (29, 3),
            (true, Trouble::NanJoints) => s.state.joints_deg[2] = f64::NAN,
            _ => {}
        }
        if !(tripped && s.trouble == Trouble::Stale) {
            s.sequence += 1;
            s.received_at = Instant::now();
        }
        Ok(StampedState {
            state: s.state.clone(),
            received_at: s.received_at,
            sequence: s.sequence,
        })
    }

    fn send(&mut self, command: &RobotCommand) -> Result<()> {
        if matches!(command, RobotCommand::ServoJ { .. }) {
            let reply = self.0.lock().unwrap().servo_reply;
            std::thread::sleep(reply);
        }
        let mut s = self.0.lock().unwrap();
        s.calls.push((Instant::now(), command.clone()));
        match command {
            RobotCommand::ServoJ { joints_deg, .. } => {
                s.servo_calls += 1;
                if s.trouble == Trouble::CallError && s.servo_calls > s.after {
                    if s.fault_at.is_none() {
                        s.fault_at = Some(Instant::now());
                    }
                    return Err(DeployError::Network {
                        call: "ServoJ".into(),
                        addr: "mock".into(),
                        message: "timed out after 200 ms".into(),
                    });
                }
                s.state.joints_deg = *joints_deg;
            }
            RobotCommand::MoveJ { joints_deg, .. } => s.state.joints_deg = *joints_deg,
            RobotCommand::MoveGripper {
                position_percent, ..
            } => s.state.gripper_position = *position_percent,
            RobotCommand::RobotEnable { enable } => s.state.enabled = *enable,
            RobotCommand::ActGripper { activate, .. } => s.state.gripper_active = *activate,
            _ => {}
        }
        Ok(())
    }
}

struct Counting(u32);

impl EpisodeHost for Counting {
    fn begin(&mut self, _: u32) -> Result<()> {
        self.0 += 1;
        Ok(())
    }
    fn outcome(&mut self) -> Result<Option<bool>> {
        Ok(None)
    }
}

fn deployment(robot: &MockRobot, live: bool, steps: u32) -> (Deployment, Arc<AtomicBool>) {
    deployment_of(robot, live, steps, 2)
}

fn deployment_of(
    robot: &MockRobot,
    live: bool,
    steps: u32,
    episodes: u32,
) -> (Deployment, Arc<AtomicBool>) {
    deployment_with(robot, &model_dir(), live, steps, episodes, 1.0)
}

/// The model in `model`, deployed on `robot` with identity calibration at `speed_scale`.
fn deployment_with(
    robot: &MockRobot,
    model: &Path,
    live: bool,
    steps: u32,
    episodes: u32,
    speed_scale: f64,
) -> (Deployment, Arc<AtomicBool>) {
    let policy = Policy::load(model).unwrap();
    let io = ModelIo::for_policy(&policy).unwrap();
    let calibration = Calibration::identity(&io.limits_rad);
    let interrupt = Arc::new(AtomicBool::new(false));
    let options = DeployOptions {
        live,
        episodes,
        max_steps: Some(steps),
        end_at_success: false,
        safety: SafetyConfig {
            speed_scale,
            ..SafetyConfig::default()
        },
        ..DeployOptions::default()
    };
    let d = Deployment::new(
        Box::new(robot.clone()),
        policy,
        calibration,
        options,
        JsonLog::create(None).unwrap(),
        interrupt.clone(),
    )
    .unwrap();
    (d, interrupt)
}

fn home() -> [f64; 6] {
    let policy = Policy::load(&model_dir()).unwrap();
    let io = ModelIo::for_policy(&policy).unwrap();
    Calibration::identity(&io.limits_rad).to_robot(&io.nominal.q)
}

fn cube() -> FixedPose {
    FixedPose(PoseMessage {
        position: [0.45, 0.02, 0.0225],
        orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
        stamp: None,
    })
}

#[test]
fn a_live_run_enables_homes_and_streams_servo_set_points() {
    let robot = MockRobot::new(home(), Trouble::None, 0);
    let (mut d, _) = deployment(&robot, true, 6);
    let ticks = d.servo_ticks() as usize;
    assert_eq!(ticks, 5, "1/30 s control in servo periods of at most 8 ms");
    assert!((d.servo_period().as_secs_f64() - 1.0 / 150.0).abs() < 1e-9);
    let mut host = Counting(0);
    let report = d.run(&mut host, &mut cube()).unwrap();
    assert!(report.fault.is_none(), "{:?}", report.fault);
    assert_eq!(report.episodes.len(), 2);
    assert_eq!(host.0, 2);
    let names: Vec<&str> = robot.calls().iter().map(|(_, c)| c.method()).collect();
    assert_eq!(
        &names[..4],
        ["RobotEnable", "SetSpeed", "ActGripper", "MoveJ"]
    );
    let first_episode: Vec<&str> = names[3..]
        .iter()
        .copied()
        .take_while(|n| *n != "ServoMoveEnd")
        .collect();
    assert_eq!(
        first_episode[..3],
        ["MoveJ", "MoveGripper", "ServoMoveStart"]
    );
    let servos = first_episode.iter().filter(|n| **n == "ServoJ").count();
    // The steps' set points, then at most a quarter second of braking to rest (180 deg/s at
    // 720 deg/s², 6.67 ms periods).
    assert!(servos >= 6 * ticks && servos <= 6 * ticks + 38, "{servos}");
    assert_eq!(names.iter().filter(|n| **n == "ServoMoveEnd").count(), 2);
}

#[test]
fn the_servo_stream_keeps_its_period_when_replies_are_slower_than_it() {
    // Each ServoJ answers after 10 ms, longer than the 6.67 ms servo period: 200 control steps,
    // 1,000 servo ticks. A loop that waits for each reply before the next tick takes 10 s;
    // the fixed schedule covers the ticks it missed with the next set point (cmdT two periods).
    let robot = MockRobot::new(home(), Trouble::None, 0).slow(Duration::from_millis(10));
    let (mut d, _) = deployment_of(&robot, true, 200, 1);
    let (ticks, period) = (d.servo_ticks() as u64, d.servo_period().as_secs_f64());
    let report = d.run(&mut Counting(0), &mut cube()).unwrap();
    assert!(report.fault.is_none(), "{:?}", report.fault);
    let calls = robot.calls();
    let servos: Vec<(Instant, f64)> = (calls.iter())
        .filter_map(|(t, c)| match c {
            RobotCommand::ServoJ { cmd_t, .. } => Some((*t, *cmd_t)),
            _ => None,
        })
        .collect();
    // Every tick of the 200 steps is covered by a set point, none given up: no send covers
    // ticks of two steps, so the sends' ticks add up to the steps' exactly (braking to rest
    // follows).
    let mut sum = 0;
    let last_of_steps = (servos.iter())
        .position(|(_, cmd_t)| {
            sum += (cmd_t / period).round() as u64;
            sum == 200 * ticks
        })
        .expect("the sends skip over the last step's final tick");
    let servos = &servos[..=last_of_steps];
    let covered = (200 * ticks) as f64;
    // The ticks kept their schedule: a send goes out once the last tick it covers is due.
    let span = (servos.last().unwrap().0 - servos[0].0).as_secs_f64();
    let measured_period = span / (covered - 1.0);
    assert!(
        (measured_period / period - 1.0).abs() < 0.05,
        "measured {:.3} ms per tick against {:.3} ms",
        measured_period * 1000.0,
        period * 1000.0
    );
    assert!(servos.iter().all(|(_, cmd_t)| *cmd_t <= 0.016 + 1e-12));
}

#[test]
fn a_dry_run_sends_nothing() {
    let robot = MockRobot::new(home(), Trouble::None, 0);
    let (mut d, _) = deployment(&robot, false, 3);
    let report = d.run(&mut Counting(0), &mut cube()).unwrap();
    assert!(report.fault.is_none());
    assert!(robot.calls().is_empty(), "{:?}", robot.calls());
}

/// Runs until the trouble strikes; returns the fault and checks the stop sequence.
fn stopped_by(trouble: Trouble) -> Fault {
    let robot = MockRobot::new(home(), trouble, 10);
    let (mut d, _) = deployment(&robot, true, 50);
    let report = d.run(&mut Counting(0), &mut cube()).unwrap();
    let fault = report.fault.expect("the trouble must stop the run");
    let calls = robot.calls();
    let n = calls.len();
    assert!(n >= 2);
    assert_eq!(calls[n - 2].1, RobotCommand::StopMotion, "{fault}");
    assert_eq!(calls[n - 1].1, RobotCommand::ServoMoveEnd, "{fault}");
    let fault_at = robot.0.lock().unwrap().fault_at.expect("fault was seen");
    let stop_at = calls[n - 2].0;
    // Stale states are detected after the deadline (50 ms); the rest at once.
    let allowed = if trouble == Trouble::Stale { 200 } else { 100 };
    let lag = stop_at.saturating_duration_since(fault_at);
    assert!(
        lag < Duration::from_millis(allowed),
        "{fault}: stopped {lag:?} after the fault"
    );
    fault
}

#[test]
fn each_fault_stops_the_arm_and_names_itself() {
    let f = stopped_by(Trouble::EStop);
    assert_eq!(f, Fault::EmergencyStop);
    assert!(f.to_string().contains("emergency stop"));
    let f = stopped_by(Trouble::FaultCode);
    assert!(
        matches!(f, Fault::ControllerFault { main_code: 29, .. }),
        "{f}"
    );
    assert!(f.to_string().contains("ServoJ joint over limit"), "{f}");
    let f = stopped_by(Trouble::Stale);
    assert!(matches!(f, Fault::StaleState { .. }), "{f}");
    let f = stopped_by(Trouble::CallError);
    assert!(
        f.to_string().contains("ServoJ") && f.to_string().contains("timed out"),
        "{f}"
    );
    let f = stopped_by(Trouble::NanJoints);
    assert!(f.to_string().contains("joint 3"), "{f}");
}

#[test]
fn ctrl_c_stops_the_arm() {
    let robot = MockRobot::new(home(), Trouble::None, 0);
    let (mut d, interrupt) = deployment(&robot, true, 200);
    let flag = interrupt.clone();
    let t = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(300));
        flag.store(true, Ordering::Relaxed);
    });
    let report = d.run(&mut Counting(0), &mut cube()).unwrap();
    t.join().unwrap();
    assert_eq!(report.fault, Some(Fault::Interrupted));
    let calls = robot.calls();
    let n = calls.len();
    assert_eq!(calls[n - 2].1, RobotCommand::StopMotion);
    assert_eq!(calls[n - 1].1, RobotCommand::ServoMoveEnd);
}

/// The home move goes at the caps in force: the controller's global override is set to the
/// speed scale's share of the FR5's top joint speed, and MoveJ's `vel` and `acc`, which the
/// controller scales by it, make up the rest of the caps.
#[test]
fn the_move_home_is_capped_by_the_speed_scale() {
    use fairgrasp_deploy::fairino::fr5;
    let robot = MockRobot::new(home(), Trouble::None, 0);
    let (mut d, _) = deployment_with(&robot, &model_dir(), true, 2, 1, 0.25);
    d.run(&mut Counting(0), &mut cube()).unwrap();
    let calls = robot.calls();
    let override_at = |i: usize| {
        calls[..i].iter().rev().find_map(|(_, c)| match c {
            RobotCommand::SetSpeed { percent } => Some(*percent as f64 / 100.0),
            _ => None,
        })
    };
    let home_move = (calls.iter())
        .position(|(_, c)| matches!(c, RobotCommand::MoveJ { .. }))
        .unwrap();
    // 45 deg/s is 24.9 % of the top speed: 25 %.
    let factor = override_at(home_move).expect("the override is set before the first move");
    assert_eq!(factor, 0.25);
    let (speed, acc) = robot
        .calls()
        .iter()
        .find_map(|(_, c)| match c {
            RobotCommand::MoveJ {
                speed_percent,
                acc_percent,
                ..
            } => Some((*speed_percent, *acc_percent)),
            _ => None,
        })
        .unwrap();
    // 180 deg/s × 0.25 and 720 deg/s² × 0.25², with the override.
    assert!(
        (speed * factor - 100.0 * 45.0 / fr5::MOVE_J_FULL_SPEED_DEG_S).abs() < 1e-9,
        "{speed}"
    );
    assert!(
        (acc * factor - 100.0 * 45.0 / fr5::MOVE_J_FULL_ACC_DEG_S2[0]).abs() < 1e-9,
        "{acc}"
    );
}

/// An arm left where the straight joint-space line home sweeps a link through the table: the
/// MoveJ is refused before it is sent, naming the part, though home itself is fine.
#[test]
fn a_move_home_through_the_table_is_never_sent() {
    let policy = Policy::load(&model_dir()).unwrap();
    let io = ModelIo::for_policy(&policy).unwrap();
    let calibration = Calibration::identity(&io.limits_rad);
    let filter = fairgrasp_deploy::safety::SafetyFilter::new(
        &SafetyConfig::default(),
        &calibration.soft_limits(),
        io.nominal.table_z * 1000.0,
        io.arm_kinematics(&calibration),
    )
    .unwrap();
    // A clear pose whose way home is not: a seeded search around home.
    let home = home();
    let (lower, upper) = filter.joint_limits();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let start = loop {
        let q: [f64; 6] = std::array::from_fn(|i| {
            (home[i] + rng.random_range(-90.0..90.0)).clamp(lower[i], upper[i])
        });
        if filter.where_outside(&q).is_none() && filter.check_path(&q, &home).is_err() {
            break q;
        }
    };
    let robot = MockRobot::new(start, Trouble::None, 0);
    let (mut d, _) = deployment(&robot, true, 4);
    let report = d.run(&mut Counting(0), &mut cube()).unwrap();
    let fault = report.fault.expect("refused").to_string();
    assert!(fault.contains("the move to"), "{fault}");
    assert!(robot.calls().iter().all(|(_, c)| c.method() != "MoveJ"));
}

/// An episode cut off mid-motion (the first steps of a policy reaching for the cube at speed
/// scale 0.25, where the ramp needs a second to reach its speed cap) brakes to rest before
/// ServoMoveEnd: the session never ends with the set points moving.
#[test]
fn the_servo_session_ends_with_the_arm_at_rest() {
    let policy = Policy::load(&deploy_model_dir()).unwrap();
    let io = ModelIo::for_policy(&policy).unwrap();
    let home = Calibration::identity(&io.limits_rad).to_robot(&io.nominal.q);
    let robot = MockRobot::new(home, Trouble::None, 0);
    let (mut d, _) = deployment_with(&robot, &deploy_model_dir(), true, 4, 1, 0.25);
    let period = d.servo_period().as_secs_f64();
    let report = d.run(&mut Counting(0), &mut cube()).unwrap();
    assert!(report.fault.is_none(), "{:?}", report.fault);
    let calls = robot.calls();
    let end = calls
        .iter()
        .position(|(_, c)| c.method() == "ServoMoveEnd")
        .unwrap();
    let set_points: Vec<[f64; 6]> = calls[..end]
        .iter()
        .filter_map(|(_, c)| match c {
            RobotCommand::ServoJ { joints_deg, .. } => Some(*joints_deg),
            _ => None,
        })
        .collect();
    let n = set_points.len();
    let speed = |k: usize| -> f64 {
        (0..6)
            .map(|i| ((set_points[k][i] - set_points[k - 1][i]) / period).abs())
            .fold(0.0, f64::max)
    };
    // It was moving when the steps ran out, and the last set point repeats none: braking
    // ended exactly at rest, its speed falling every period.
    let moving = (1..n).map(speed).fold(0.0, f64::max);
    assert!(moving > 1.0, "the arm never moved ({moving} deg/s)");
    // The last period's speed is below one period of braking at 720 deg/s² × 0.25².
    let last = speed(n - 1);
    let stopping = (n.saturating_sub(8).max(1)..n)
        .map(speed)
        .collect::<Vec<_>>();
    assert!(
        last <= 45.0 * period + 1e-6,
        "still moving at {last} deg/s: {stopping:?}"
    );
    assert!(
        stopping
            .windows(2)
            .rev()
            .take(3)
            .all(|w| w[1] <= w[0] + 1e-6),
        "{stopping:?}"
    );
}

/// A perception that stops sending: its last pose, received once and never again.
struct SilentPerception(ReceivedPose);

impl PoseSource for SilentPerception {
    fn latest(&mut self) -> Result<Option<ReceivedPose>> {
        Ok(Some(self.0.clone()))
    }
}

/// A pose that stops updating stops the arm once it is older than `pose_deadline_ms`; it was
/// acted on at any age.
#[test]
fn a_pose_older_than_its_deadline_stops_the_arm() {
    let robot = MockRobot::new(home(), Trouble::None, 0);
    let (mut d, _) = deployment_of(&robot, true, 40, 1);
    let mut pose = SilentPerception(ReceivedPose {
        message: cube().0,
        received_at: Instant::now(),
    });
    let report = d.run(&mut Counting(0), &mut pose).unwrap();
    match report.fault {
        Some(Fault::StalePose {
            age_ms,
            deadline_ms,
        }) => {
            assert_eq!(deadline_ms, 250.0);
            assert!((250.0..300.0).contains(&age_ms), "{age_ms}");
        }
        other => panic!("{other:?}"),
    }
    // Nothing moved the arm after the stop.
    let calls = robot.calls();
    let stop = calls
        .iter()
        .position(|(_, c)| c.method() == "StopMotion")
        .unwrap();
    assert!(calls[stop..].iter().all(|(_, c)| !c.moves()));
}
