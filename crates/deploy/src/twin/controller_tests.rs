//! The controller state machine driven by a perfect plant (the arm is where the set point is),
//! with simulated time: no clock, no network, no physics.

use super::controller::{
    Controller, ControllerConfig, MAIN_CODE_EMERGENCY_STOP, Measured, StartState, codes,
};
use super::motion::{Joints, max_gap};
use fairgrasp_sim::kinematics::SerialChain;

const HOME: Joints = [10.0, -90.0, -100.0, -80.0, 90.0, 0.0];
const DT: f64 = 0.004;

struct Bench {
    c: Controller,
    t: f64,
    q: Joints,
    gripper: f64,
}

impl Bench {
    fn new(start: StartState) -> Self {
        let model = fairgrasp_sim::assets::fr5().unwrap();
        let chain = SerialChain::new(&model, "tool0").unwrap();
        let config = ControllerConfig::fr5(&chain.limits, start);
        Self {
            c: Controller::new(config, chain, HOME, 0.0),
            t: 0.0,
            q: HOME,
            gripper: 100.0,
        }
    }

    fn started() -> Self {
        let mut b = Self::new(StartState::default());
        assert_eq!(b.c.act_gripper(1, 1), codes::OK);
        b
    }

    /// One plant step: the arm follows the set point exactly, the fingers at 400 %/s, closing
    /// no further than `stop_at` (an object).
    fn tick_with_object(&mut self, stop_at: f64) {
        self.t += DT;
        let sp = self.c.setpoint(self.t);
        let speeds: Joints = std::array::from_fn(|j| (sp.joints_deg[j] - self.q[j]) / DT);
        self.q = sp.joints_deg;
        let step = 400.0 * DT;
        self.gripper =
            (self.gripper + (sp.gripper_percent - self.gripper).clamp(-step, step)).max(stop_at);
        self.c.observe(
            self.t,
            Measured {
                joints_deg: self.q,
                joint_speeds_deg: speeds,
                gripper_percent: self.gripper,
            },
        );
    }

    fn run(&mut self, seconds: f64) {
        let n = (seconds / DT).round() as usize;
        for _ in 0..n {
            self.tick_with_object(0.0);
        }
    }

    /// Runs until `ticket` ends; returns its code and the time it took.
    fn wait(&mut self, ticket: u64) -> (i32, f64) {
        let start = self.t;
        for _ in 0..10_000 {
            if let Some(code) = self.c.outcome(ticket) {
                return (code, self.t - start);
            }
            self.tick_with_object(0.0);
        }
        panic!("move {ticket} never ended");
    }
}

fn target() -> Joints {
    [30.0, -80.0, -90.0, -85.0, 80.0, 20.0]
}

#[test]
fn enable_and_mode_gate_motion() {
    let mut b = Bench::new(StartState {
        enabled: false,
        automatic: false,
        gripper_active: false,
    });
    assert_eq!(
        b.c.move_j(0.0, target(), 50.0, 0.0, 100.0),
        Err(codes::NOT_ENABLED)
    );
    assert_eq!(b.c.servo_start(), codes::NOT_ENABLED);
    assert_eq!(b.c.enable(0.0, true), codes::OK);
    assert_eq!(
        b.c.move_j(0.0, target(), 50.0, 0.0, 100.0),
        Err(codes::EXECUTION_FAILED),
        "manual mode refuses remote motion"
    );
    assert_eq!(b.c.set_mode(0.0, 7), codes::PARAM_VALUE);
    assert_eq!(b.c.set_mode(0.0, 0), codes::OK);
    assert!(b.c.state().robot_mode == 0 && b.c.state().enabled);
    let ticket = b.c.move_j(0.0, target(), 50.0, 0.0, 100.0).unwrap();
    // Disabling mid-move aborts it with "not enabled".
    b.run(0.1);
    assert_eq!(b.c.enable(b.t, false), codes::OK);
    assert_eq!(b.c.outcome(ticket), Some(codes::NOT_ENABLED));
    assert!(!b.c.state().enabled);
}

#[test]
fn move_j_reports_moving_then_done_and_arrives() {
    let mut b = Bench::started();
    assert!(b.c.state().motion_done);
    let ticket = b.c.move_j(b.t, target(), 20.0, 0.0, 100.0).unwrap();
    b.tick_with_object(0.0);
    let s = b.c.state();
    assert!(!s.motion_done && s.robot_state == 2, "moving: {s:?}");
    assert_eq!(b.c.outcome(ticket), None);
    let (code, seconds) = b.wait(ticket);
    assert_eq!(code, codes::OK);
    // 20° on j1 at 20 % of 180°/s: 1.875 × 20 / 36 ≈ 1.04 s with the quintic law.
    assert!((0.9..1.5).contains(&seconds), "took {seconds} s");
    let s = b.c.state();
    assert!(s.motion_done && s.robot_state == 1);
    assert!(max_gap(&s.joints_deg, &target()) < 1e-6);
    // SetSpeed halves the speed: the move back takes about twice as long.
    assert_eq!(b.c.set_speed(10.0), codes::OK);
    assert_eq!(b.c.set_speed(0.0), codes::PARAM_VALUE);
    let back = b.c.move_j(b.t, HOME, 20.0, 0.0, 100.0).unwrap();
    let (_, slower) = b.wait(back);
    assert!(slower > 8.0 * seconds, "{slower} vs {seconds}");
}

#[test]
fn move_j_checks_its_arguments_and_queues() {
    let mut b = Bench::started();
    let mut over = target();
    over[2] = 400.0;
    assert_eq!(
        b.c.move_j(0.0, over, 20.0, 0.0, 100.0),
        Err(codes::PARAM_VALUE)
    );
    assert_eq!(
        b.c.move_j(0.0, target(), 0.0, 0.0, 100.0),
        Err(codes::PARAM_VALUE)
    );
    assert_eq!(
        b.c.move_j(0.0, target(), f64::NAN, 0.0, 100.0),
        Err(codes::PARAM_VALUE)
    );
    let first = b.c.move_j(0.0, target(), 100.0, 0.0, 100.0).unwrap();
    let second = b.c.move_j(0.0, HOME, 100.0, 0.0, 100.0).unwrap();
    assert_eq!(b.wait(first).0, codes::OK);
    assert_eq!(
        b.c.outcome(second),
        None,
        "the second move runs after the first"
    );
    assert_eq!(b.wait(second).0, codes::OK);
    assert!(max_gap(&b.q, &HOME) < 1e-6);
}

#[test]
fn a_servo_session_moves_the_arm_along_its_targets() {
    let mut b = Bench::started();
    let mut q = HOME;
    assert_eq!(
        b.c.servo_j(b.t, q, 0.008),
        codes::EXECUTION_FAILED,
        "no session yet"
    );
    assert_eq!(b.c.servo_start(), codes::OK);
    assert_eq!(
        b.c.move_j(b.t, target(), 20.0, 0.0, 100.0),
        Err(codes::EXECUTION_FAILED)
    );
    for _ in 0..100 {
        q[0] += 0.1;
        assert_eq!(b.c.servo_j(b.t, q, 0.008), codes::OK);
        b.run(0.008);
        assert!(max_gap(&b.q, &q) < 1e-6, "each target reached over cmdT");
    }
    assert!((b.q[0] - (HOME[0] + 10.0)).abs() < 1e-6);
    assert_eq!(
        b.c.servo_j(b.t, q, 0.5),
        codes::PARAM_VALUE,
        "cmdT out of range"
    );
    let mut over = q;
    over[1] = -300.0;
    assert_eq!(b.c.servo_j(b.t, over, 0.008), codes::SERVOJ_OVER_LIMIT);
    b.run(0.05);
    assert!(
        max_gap(&b.q, &q) < 1e-6,
        "an over-limit target does not move the arm"
    );
    // A jump is followed no faster than the joint speed limit.
    let mut far = q;
    far[0] += 30.0;
    assert_eq!(b.c.servo_j(b.t, far, 0.008), codes::OK);
    b.run(0.008);
    assert!(
        b.q[0] - q[0] < 181.0 * 0.0081,
        "rate limited: {}",
        b.q[0] - q[0]
    );
    assert_eq!(b.c.servo_end(), codes::OK);
    b.run(0.3);
    assert!(
        max_gap(&b.q, &far) < 1e-6,
        "the last target is still reached"
    );
    assert!(b.c.state().motion_done);
    assert_eq!(
        b.c.servo_j(b.t, q, 0.008),
        codes::EXECUTION_FAILED,
        "session ended"
    );
}

#[test]
fn stop_motion_aborts_a_move() {
    let mut b = Bench::started();
    let ticket = b.c.move_j(b.t, target(), 20.0, 0.0, 100.0).unwrap();
    b.run(0.3);
    let before = b.q;
    assert_eq!(b.c.stop_motion(b.t), codes::OK);
    assert_eq!(b.c.outcome(ticket), Some(codes::EXECUTION_FAILED));
    b.run(0.3);
    assert!(
        max_gap(&b.q, &before) < 0.2,
        "the arm stays where it was stopped"
    );
    assert!(max_gap(&b.q, &target()) > 5.0);
    assert!(b.c.state().motion_done);
}

#[test]
fn the_gripper_must_be_activated_and_reports_its_motion() {
    let mut b = Bench::new(StartState::default());
    assert!(!b.c.state().gripper_active);
    assert_eq!(
        b.c.move_gripper(b.t, 1, [0, 50, 50], 5000),
        Err(codes::GRIPPER_MOTION)
    );
    assert_eq!(b.c.act_gripper(9, 1), codes::PARAM_VALUE);
    assert_eq!(b.c.act_gripper(1, 1), codes::OK);
    assert_eq!(
        b.c.move_gripper(b.t, 1, [150, 50, 50], 5000),
        Err(codes::PARAM_VALUE)
    );
    let command = b.c.move_gripper(b.t, 1, [0, 50, 50], 5000).unwrap();
    assert!(b.c.gripper_moving(command));
    assert_eq!(b.c.gripper_motion_done(), (0, 0));
    // An object stops the fingers at 40 %: the motion is done by the stall.
    for _ in 0..200 {
        b.tick_with_object(40.0);
    }
    assert!(!b.c.gripper_moving(command));
    let s = b.c.state();
    assert!(s.gripper_motion_done && s.gripper_position == 40, "{s:?}");
    assert_eq!(b.c.gripper_motion_done(), (0, 1));
    assert_eq!(b.c.act_gripper(1, 0), codes::OK);
    assert_eq!(
        b.c.move_gripper(b.t, 1, [100, 50, 50], 5000),
        Err(codes::GRIPPER_MOTION)
    );
}

#[test]
fn the_e_stop_stops_refuses_and_shows_in_main_code() {
    let mut b = Bench::started();
    let ticket = b.c.move_j(b.t, target(), 20.0, 0.0, 100.0).unwrap();
    b.run(0.2);
    b.c.set_estop(b.t, true);
    assert_eq!(b.c.outcome(ticket), Some(codes::EMERGENCY_STOP));
    let s = b.c.state();
    assert!(s.emergency_stop);
    assert_eq!((s.main_code, s.sub_code), MAIN_CODE_EMERGENCY_STOP);
    assert_eq!(
        b.c.move_j(b.t, target(), 20.0, 0.0, 100.0),
        Err(codes::EMERGENCY_STOP)
    );
    assert_eq!(b.c.servo_start(), codes::EMERGENCY_STOP);
    assert_eq!(
        b.c.move_gripper(b.t, 1, [0, 50, 50], 0),
        Err(codes::EMERGENCY_STOP)
    );
    assert_eq!(b.c.reset_errors(), codes::EXECUTION_FAILED, "still pressed");
    b.c.set_estop(b.t, false);
    assert_eq!(
        b.c.move_j(b.t, target(), 20.0, 0.0, 100.0),
        Err(codes::EXECUTION_FAILED),
        "the fault stays until reset"
    );
    assert_eq!(b.c.reset_errors(), codes::OK);
    assert_eq!(b.c.state().main_code, 0);
    assert!(b.c.move_j(b.t, target(), 20.0, 0.0, 100.0).is_ok());
}

#[test]
fn a_safety_stop_refuses_motion_with_99() {
    let mut b = Bench::started();
    assert_eq!(b.c.servo_start(), codes::OK);
    b.c.set_safety_stop(b.t, [false, true]);
    assert_eq!(b.c.servo_j(b.t, HOME, 0.008), codes::SAFETY_STOP);
    assert_eq!(
        b.c.move_j(b.t, target(), 20.0, 0.0, 100.0),
        Err(codes::SAFETY_STOP)
    );
    assert_eq!(
        b.c.move_gripper(b.t, 1, [0, 50, 50], 0),
        Err(codes::SAFETY_STOP)
    );
    assert_eq!(b.c.state().safety_stop, [false, true]);
    b.c.set_safety_stop(b.t, [false, false]);
    assert_eq!(
        b.c.servo_j(b.t, HOME, 0.008),
        codes::EXECUTION_FAILED,
        "the stop ended the session"
    );
    assert!(b.c.move_j(b.t, target(), 20.0, 0.0, 100.0).is_ok());
}

#[test]
fn injected_faults_stop_the_arm_and_reset_when_resettable() {
    let mut b = Bench::started();
    let ticket = b.c.move_j(b.t, target(), 20.0, 0.0, 100.0).unwrap();
    b.run(0.1);
    b.c.set_fault(b.t, 5, 7, false);
    assert_eq!(b.c.outcome(ticket), Some(codes::EXECUTION_FAILED));
    assert_eq!((b.c.state().main_code, b.c.state().sub_code), (5, 7));
    assert_eq!(b.c.reset_errors(), codes::NOT_RESETTABLE);
    b.c.set_fault(b.t, 2, 1, true);
    assert_eq!(b.c.reset_errors(), codes::OK);
    assert_eq!(b.c.state().main_code, 0);
}

#[test]
fn kinematics_round_trip_through_the_wire_format() {
    let b = Bench::started();
    let pose = b.c.forward_kin(&target()).unwrap();
    let q = b.c.inverse_kin(&pose).unwrap();
    let again = b.c.forward_kin(&q).unwrap();
    for k in 0..3 {
        assert!((pose[k] - again[k]).abs() < 0.1, "{pose:?} vs {again:?}");
    }
    assert_eq!(
        b.c.inverse_kin(&[5000.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        Err(codes::IK_FAILED)
    );
    assert_eq!(b.c.forward_kin(&[f64::NAN; 6]), Err(codes::PARAM_VALUE));
    // The reported TCP is the forward kinematics of the reported joints.
    let s = b.c.state();
    assert_eq!(s.tcp, b.c.forward_kin(&s.joints_deg).unwrap());
}
