//! The controller state machine driven by a perfect plant (the arm is where the set point is),
//! with simulated time: no clock, no network, no physics.

use super::controller::{
    Controller, ControllerConfig, DEFAULT_BRAKE_DECEL_DEG_S2, MAIN_CODE_EMERGENCY_STOP,
    MAIN_CODE_FOLLOWING_ERROR, MAIN_CODE_SERVOJ_OVER_LIMIT, Measured, StartState,
};
use super::faults::JointTracking;
use super::motion::{Joints, max_gap};
use crate::fairino::error_codes::codes;
use crate::fairino::fr5::MAX_SPEED_DEG_S;
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
                ..Measured::default()
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

impl Bench {
    /// Streams ServoJ every 8 ms moving `joint` at `speed` deg/s for `seconds`; returns the
    /// last target.
    fn stream(&mut self, joint: usize, speed: f64, seconds: f64) -> Joints {
        assert_eq!(self.c.servo_start(), codes::OK);
        let mut q = self.c.command();
        for _ in 0..(seconds / 0.008).round() as usize {
            q[joint] += speed * 0.008;
            assert_eq!(self.c.servo_j(self.t, q, 0.008), codes::OK);
            self.run(0.008);
        }
        q
    }

    /// Runs until the controller reports the arm still; returns how long that took.
    fn until_still(&mut self) -> f64 {
        let start = self.t;
        while !self.c.state().motion_done {
            assert!(self.t - start < 10.0, "never came to rest");
            self.tick_with_object(0.0);
        }
        self.t - start
    }
}

/// The braking distance from `speed` at the default deceleration.
fn braking_distance(speed: f64) -> f64 {
    speed * speed / (2.0 * DEFAULT_BRAKE_DECEL_DEG_S2)
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
    let mut far = q;
    far[0] += 1.0;
    assert_eq!(b.c.servo_j(b.t, far, 0.008), codes::OK);
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

#[test]
fn the_speed_override_caps_servo_motion_and_a_faster_stream_falls_behind() {
    // 0.8° every 8 ms: 100°/s, under the top speed, over 25 % of it (45°/s).
    let stream = |b: &mut Bench| {
        assert_eq!(b.c.servo_start(), codes::OK);
        let mut q = HOME;
        let mut fastest: f64 = 0.0;
        for _ in 0..25 {
            q[0] += 0.8;
            let before = b.q[0];
            assert_eq!(b.c.servo_j(b.t, q, 0.008), codes::OK);
            b.run(0.008);
            fastest = fastest.max((b.q[0] - before) / 0.008);
        }
        (q[0] - b.q[0], fastest)
    };
    let mut full = Bench::started();
    let (behind, fastest) = stream(&mut full);
    assert!(
        behind < 1e-6 && (fastest - 100.0).abs() < 1.0,
        "{behind}° {fastest}°/s"
    );
    let mut slowed = Bench::started();
    assert_eq!(slowed.c.set_speed(25.0), codes::OK);
    let (behind, fastest) = stream(&mut slowed);
    let cap = MAX_SPEED_DEG_S[0] * 0.25;
    assert!(fastest <= cap + 1e-6, "{fastest}°/s over {cap}°/s");
    // 200 ms at 100°/s asked, at most 45°/s done: 11° behind.
    assert!(behind > 10.0, "{behind}°");
}

#[test]
fn a_servo_target_past_a_joint_limit_raises_29_and_the_arm_brakes() {
    let mut b = Bench::started();
    let speed = 120.0;
    let q = b.stream(1, speed, 0.2);
    let at_stop = b.q;
    let mut over = q;
    over[1] = -300.0;
    assert_eq!(b.c.servo_j(b.t, over, 0.008), codes::SERVOJ_OVER_LIMIT);
    let s = b.c.state();
    assert_eq!((s.main_code, s.sub_code), (MAIN_CODE_SERVOJ_OVER_LIMIT, 2));
    assert!(!s.motion_done, "braking: still moving");
    let took = b.until_still();
    // Braking from 120 deg/s at 720 deg/s²: 1/6 s, 10° further on.
    let overshoot = b.q[1] - at_stop[1];
    assert!(
        (overshoot - braking_distance(speed)).abs() < 0.05 * braking_distance(speed),
        "overshoot {overshoot}° in {took} s"
    );
    assert!(
        (took - speed / DEFAULT_BRAKE_DECEL_DEG_S2).abs() < 0.01,
        "{took} s"
    );
    assert_eq!(
        b.c.servo_j(b.t, q, 0.008),
        codes::EXECUTION_FAILED,
        "the fault ended the session"
    );
    assert_eq!(b.c.servo_start(), codes::EXECUTION_FAILED, "until reset");
    assert_eq!(b.c.reset_errors(), codes::OK);
    assert_eq!(b.c.state().main_code, 0);
    assert_eq!(b.c.servo_start(), codes::OK);
}

#[test]
fn a_servo_step_faster_than_the_joint_raises_29() {
    let top = MAX_SPEED_DEG_S[0];
    let mut b = Bench::started();
    assert_eq!(b.c.servo_start(), codes::OK);
    let mut q = HOME;
    // 4 % over the top speed passes the default 5 % tolerance; so does a late send covering
    // two ticks with cmdT doubled.
    q[0] += 1.04 * top * 0.008;
    assert_eq!(b.c.servo_j(b.t, q, 0.008), codes::OK);
    b.run(0.008);
    q[0] += 1.04 * top * 0.016;
    assert_eq!(b.c.servo_j(b.t, q, 0.016), codes::OK);
    b.run(0.016);
    // The same two-tick step in one tick's cmdT is twice too fast.
    q[0] += 1.04 * top * 0.016;
    assert_eq!(b.c.servo_j(b.t, q, 0.008), codes::SERVOJ_OVER_LIMIT);
    let s = b.c.state();
    assert_eq!((s.main_code, s.sub_code), (MAIN_CODE_SERVOJ_OVER_LIMIT, 11));
    assert!(!s.motion_done, "the arm brakes from its speed");
    b.until_still();
    assert_eq!(b.c.reset_errors(), codes::OK);
    // Without tolerance the 4 % is too fast.
    b.c.set_servo_speed_tolerance(0.0);
    assert_eq!(b.c.servo_start(), codes::OK);
    let mut q = b.c.command();
    q[0] += 1.04 * top * 0.008;
    assert_eq!(b.c.servo_j(b.t, q, 0.008), codes::SERVOJ_OVER_LIMIT);
}

#[test]
fn stop_motion_and_the_e_stop_brake_with_an_overshoot() {
    for estop in [false, true] {
        let mut b = Bench::started();
        let ticket = b.c.move_j(b.t, target(), 100.0, 100.0, 100.0).unwrap();
        b.run(0.15);
        let speed = b.c.state().joint_speeds_deg[0];
        assert!(speed > 40.0, "moving fast: {speed}");
        let at_stop = b.q;
        if estop {
            b.c.set_estop(b.t, true);
        } else {
            assert_eq!(b.c.stop_motion(b.t), codes::OK);
        }
        assert!(b.c.outcome(ticket).is_some());
        // Half way through the brake the reported speed is half the speed at the stop.
        let brake = speed / DEFAULT_BRAKE_DECEL_DEG_S2;
        b.run(brake / 2.0);
        let half = b.c.state().joint_speeds_deg[0];
        assert!(
            (half - speed / 2.0).abs() < 0.05 * speed,
            "{half} of {speed}"
        );
        assert!(!b.c.state().motion_done);
        b.until_still();
        let overshoot = b.q[0] - at_stop[0];
        assert!(
            (overshoot - braking_distance(speed)).abs() < 0.05 * braking_distance(speed) + 0.01,
            "e-stop {estop}: {overshoot}° vs {}°",
            braking_distance(speed)
        );
        b.run(0.2);
        assert!((b.q[0] - at_stop[0] - overshoot).abs() < 1e-9, "at rest");
    }
}

#[test]
fn a_move_sent_while_braking_starts_after_the_brake() {
    let mut b = Bench::started();
    b.c.move_j(b.t, target(), 100.0, 100.0, 100.0).unwrap();
    b.run(0.15);
    assert_eq!(b.c.stop_motion(b.t), codes::OK);
    assert_eq!(b.c.servo_start(), codes::EXECUTION_FAILED, "still braking");
    let back = b.c.move_j(b.t, HOME, 50.0, 0.0, 100.0).unwrap();
    assert_eq!(b.wait(back).0, codes::OK);
    assert!(max_gap(&b.q, &HOME) < 1e-6);
}

/// A 1° servo step on j2 with the drives delayed 20 ms and lagging 50 ms: the reported joint
/// starts moving 20 ms later and closes the gap with a 50 ms time constant.
#[test]
fn the_drives_delay_and_lag_show_in_the_reported_joints() {
    let (delay, tau) = (0.020, 0.050);
    let mut b = Bench::started();
    b.c.set_tracking(
        [JointTracking {
            delay_ms: delay * 1e3,
            tau_ms: tau * 1e3,
        }; 6],
    );
    b.run(0.1);
    assert_eq!(b.c.servo_start(), codes::OK);
    let start = b.t;
    let mut q = HOME;
    q[1] += 1.0;
    let ramp = 0.008;
    assert_eq!(b.c.servo_j(start, q, ramp), codes::OK);
    let mut trace = Vec::new();
    for _ in 0..200 {
        b.tick_with_object(0.0);
        trace.push((b.t - start, b.c.state().joints_deg[1] - HOME[1]));
    }
    let moved_at = trace.iter().find(|(_, y)| *y > 1e-6).unwrap().0;
    // The first tick after the delay shows the move (ticks are 4 ms).
    assert!(
        moved_at > delay && moved_at <= delay + DT + 1e-9,
        "moved at {moved_at} s"
    );
    // ln(1 - y) falls with slope -1/tau once the delayed ramp has passed.
    let fit: Vec<(f64, f64)> = trace
        .iter()
        .filter(|(t, _)| *t > delay + ramp && *t < delay + 3.0 * tau)
        .map(|(t, y)| (*t, (1.0 - y).ln()))
        .collect();
    let n = fit.len() as f64;
    let (mt, my) = (
        fit.iter().map(|p| p.0).sum::<f64>() / n,
        fit.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let slope = fit.iter().map(|(t, y)| (t - mt) * (y - my)).sum::<f64>()
        / fit.iter().map(|(t, _)| (t - mt).powi(2)).sum::<f64>();
    let measured_tau = -1.0 / slope;
    assert!(
        (measured_tau - tau).abs() < 0.03 * tau,
        "time constant {measured_tau} s"
    );
    // The line crosses 0 where the delayed ramp is half done: the delay.
    let measured_delay = mt - my / slope - ramp / 2.0;
    assert!(
        (measured_delay - delay).abs() < 0.03 * delay,
        "delay {measured_delay} s"
    );
    assert_eq!(b.c.tracking()[1].tau_ms, 50.0);
    assert_eq!(b.c.state().main_code, 0, "a 1° lag is no following error");
}

#[test]
fn a_joint_far_behind_its_set_point_is_a_following_error() {
    let mut b = Bench::started();
    b.c.set_tracking(
        [JointTracking {
            delay_ms: 0.0,
            tau_ms: 5_000.0,
        }; 6],
    );
    b.c.set_following_error(Some(5.0));
    assert_eq!(b.c.servo_start(), codes::OK);
    let mut q = HOME;
    let mut faulted = None;
    for _ in 0..100 {
        q[2] += 0.4;
        if b.c.servo_j(b.t, q, 0.008) != codes::OK {
            faulted = Some(b.t);
            break;
        }
        b.run(0.008);
    }
    let s = b.c.state();
    assert_eq!((s.main_code, s.sub_code), (MAIN_CODE_FOLLOWING_ERROR, 3));
    assert!(faulted.is_some(), "the fault refused the stream");
    assert!(
        (b.c.command()[2] - b.q[2]).abs() > 5.0,
        "the set point ran ahead of the joint"
    );
    assert_eq!(
        b.c.move_j(b.t, HOME, 20.0, 0.0, 100.0),
        Err(codes::EXECUTION_FAILED)
    );
    // Without the check the same lag is allowed.
    b.c.set_following_error(None);
    b.c.set_tracking(Default::default());
    assert_eq!(b.c.reset_errors(), codes::OK);
    b.until_still();
    assert_eq!(b.c.state().main_code, 0);
}

/// The drives' lag adds to the braking distance: the arm travels v²/2a plus about
/// v × (delay + tau) after an e-stop.
#[test]
fn the_drives_lag_adds_to_the_braking_overshoot() {
    let (delay, tau) = (0.008, 0.015);
    let mut b = Bench::started();
    b.c.set_tracking(
        [JointTracking {
            delay_ms: delay * 1e3,
            tau_ms: tau * 1e3,
        }; 6],
    );
    let speed = 100.0;
    b.stream(0, speed, 0.3);
    let at_stop = b.q[0];
    b.c.set_estop(b.t, true);
    b.until_still();
    b.run(0.3);
    let travel = b.q[0] - at_stop;
    let expected = braking_distance(speed) + speed * (delay + tau);
    assert!(
        (travel - expected).abs() < 0.05 * expected,
        "{travel}° vs {expected}°"
    );
}
