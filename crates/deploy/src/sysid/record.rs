//! Running the excitation on the arm and recording it: every set point sent and every state
//! received, then the gripper closing on nothing.
//!
//! The set points stream on the servo schedule ([`ServoClock`]), each from the
//! [`SafetyFilter`]; every tick the newest state goes through the [`Watchdog`] and the Ctrl-C
//! flag is looked at. Any fault stops the arm (StopMotion, then ServoMoveEnd) and ends the
//! run with it. A dry run prints the plan, checks each joint's path, and sends nothing.

use super::model::GripperTiming;
use super::plan::{ExcitationPlan, Segment};
use crate::error::{DeployError, Result};
use crate::robot::{RobotCommand, RobotLink, StampedState};
use crate::runner::{MAX_CMD_T, ServoClock, describe};
use crate::safety::{Fault, SafetyFilter, Watchdog};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How often states are looked for between ticks: the stream sends one every 8 ms.
const POLL: Duration = Duration::from_millis(1);
/// Recording goes on this long after the last set point (s).
const TAIL_S: f64 = 0.3;
/// The gripper's whole close may take this long before it counts as not moving (s).
const GRIPPER_TIMEOUT_S: f64 = 8.0;
/// The gripper has ended its move once its reported position has not changed for this long (s).
const GRIPPER_STILL_S: f64 = 0.4;
/// A set point is looked for in the states from this long before its call to this long after
/// its reply, by the rough clock offset (s): far wider than that offset's error, far shorter
/// than the time a set point takes to come back (a step and back lasts 0.5 s).
const SEARCH_BEFORE_S: f64 = 0.05;
const SEARCH_AFTER_S: f64 = 0.1;
/// Stopping further open than this (%) with nothing between the fingers is a stall.
const STALL_PERCENT: f64 = 3.0;
/// The set points go out this much slower than the safety filter's period, so that their
/// arrivals drift across the controller's stream frames (0.125 ms a tick on the 8 ms stream,
/// a whole frame every 64 ticks): some arrive just before a frame and some just after, and the
/// clock offset is bounded as tightly from both sides. Sent on the stream's own period, the
/// phase stayed put and the offset came out up to 0.7 ms off (the simulated controller at a
/// fixed 0.5 ms latency), which the fit read as the arm's delay. Slower ticks only lower the
/// filter's speeds and accelerations.
const SEND_STRETCH: f64 = 1.0 + 1.0 / 64.0;

/// One set point sent.
#[derive(Clone, Debug, PartialEq)]
pub struct SentSetPoint {
    /// When it reached the controller (s from the recording's start): halfway through the call.
    pub t: f64,
    /// When the call began and when its reply came (s): it reached the controller between.
    pub sent: f64,
    /// When its reply came (s).
    pub replied: f64,
    /// The set point (deg).
    pub joints_deg: [f64; 6],
    /// Its cmdT (s).
    pub cmd_t: f64,
}

/// One state received.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordedState {
    /// When it arrived (s from the recording's start).
    pub received: f64,
    /// The controller's clock in it (ms), when the stream carries one.
    pub clock_ms: Option<i64>,
    /// Joint angles (deg).
    pub joints_deg: [f64; 6],
    /// The last ServoJ target the controller had received by its clock, when the stream
    /// carries it.
    pub servo_target: Option<[f64; 6]>,
}

/// What the excitation did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Recording {
    /// The measured pose the excitation was about (deg).
    pub start_deg: [f64; 6],
    /// Every set point sent, in order.
    pub commands: Vec<SentSetPoint>,
    /// Every state received, in order.
    pub states: Vec<RecordedState>,
    /// Each joint's share, in the recording's time.
    pub segments: Vec<Segment>,
    /// The gripper's close on nothing, when it was measured.
    pub gripper: Option<GripperTiming>,
}

impl Recording {
    /// The recording with every joint vector mapped by `f` (robot degrees to the simulator's,
    /// through a calibration).
    pub fn map_joints(&self, f: impl Fn(&[f64; 6]) -> [f64; 6]) -> Self {
        Self {
            start_deg: f(&self.start_deg),
            commands: (self.commands.iter())
                .map(|c| SentSetPoint {
                    joints_deg: f(&c.joints_deg),
                    ..c.clone()
                })
                .collect(),
            states: (self.states.iter())
                .map(|s| RecordedState {
                    joints_deg: f(&s.joints_deg),
                    servo_target: s.servo_target.as_ref().map(&f),
                    ..s.clone()
                })
                .collect(),
            ..self.clone()
        }
    }

    /// When each state was taken, on the recording's clock (s): the controller's clock moved
    /// by its offset from ours ([`Recording::clock_offset`]). Without the controller's clock,
    /// or if it steps back: the arrival times.
    pub fn state_times(&self) -> Vec<f64> {
        match self.clock_offset() {
            Some((offset, clocks)) => clocks.iter().map(|&c| c as f64 / 1e3 + offset).collect(),
            None => self.states.iter().map(|s| s.received).collect(),
        }
    }

    /// Our clock minus the controller's (s), with the controller's clock of each state (ms).
    ///
    /// With `last_servoJ_target` in the stream, each new set point reached the controller
    /// after the clock of the last state without it and by the clock of the first with it,
    /// and on our clock between its call and the reply: each set point bounds the offset from
    /// both sides, and the offset is the middle of what all of them allow. Otherwise: the
    /// smallest gap between a state's arrival and its clock (a frame sent at once), which
    /// also counts the frame's time on its way; that bias reads as the arm's delay.
    pub fn clock_offset(&self) -> Option<(f64, Vec<i64>)> {
        let clocks = self.clocks()?;
        let offset = match self.arrivals(&clocks) {
            Some(arrivals) => arrivals.offset(),
            None => self.earliest_gap(&clocks),
        };
        Some((offset, clocks))
    }

    /// The recording with each set point's time (`t`) narrowed, where a state showed it
    /// arrive, to what both clocks allow, and kept in order between those; unchanged without
    /// `last_servoJ_target`. Halfway through the call is late by however long this process
    /// waited for the reply, which a loaded host stretches to milliseconds.
    pub fn aligned(&self) -> Self {
        let mut out = self.clone();
        let Some(arrivals) = self.clocks().and_then(|c| self.arrivals(&c)) else {
            return out;
        };
        let offset = arrivals.offset();
        for &(k, after_ms, by_ms) in &arrivals.seen {
            let c = &mut out.commands[k];
            let from = c.sent.max(after_ms as f64 / 1e3 - 0.0005 + offset);
            let to = c.replied.min(by_ms as f64 / 1e3 + 0.0005 + offset);
            if from <= to {
                c.t = 0.5 * (from + to);
            }
        }
        // The others in order between their neighbours.
        let mut seen = arrivals.seen.iter().map(|a| a.0).peekable();
        let mut floor = f64::NEG_INFINITY;
        for k in 0..out.commands.len() {
            if seen.peek() == Some(&k) {
                seen.next();
                floor = out.commands[k].t;
                continue;
            }
            let ceiling = seen.peek().map_or(f64::INFINITY, |&n| out.commands[n].t);
            let c = &mut out.commands[k];
            c.t = c.t.clamp(floor, ceiling.max(floor));
            floor = c.t;
        }
        out
    }

    fn clocks(&self) -> Option<Vec<i64>> {
        let clocks: Vec<i64> = self
            .states
            .iter()
            .map(|s| s.clock_ms)
            .collect::<Option<_>>()?;
        (!clocks.is_empty() && clocks.windows(2).all(|w| w[1] >= w[0])).then_some(clocks)
    }

    /// The smallest gap between a state's arrival and its clock (s), plus half the clock's
    /// millisecond.
    fn earliest_gap(&self, clocks: &[i64]) -> f64 {
        (self.states.iter().zip(clocks))
            .map(|(s, &c)| s.received - c as f64 / 1e3)
            .fold(f64::INFINITY, f64::min)
            + 0.0005
    }

    /// The set points seen arriving in `last_servoJ_target`, and the offset's bounds they
    /// give, each widened by half the clock's millisecond. Each set point is looked for in
    /// the states that the earliest gap (an offset a few ms off) puts near its call.
    fn arrivals(&self, clocks: &[i64]) -> Option<Arrivals> {
        let targets: Vec<[f64; 6]> = (self.states.iter())
            .map(|s| s.servo_target)
            .collect::<Option<_>>()?;
        let rough = self.earliest_gap(clocks);
        let times: Vec<f64> = clocks.iter().map(|&c| c as f64 / 1e3 + rough).collect();
        let same = |a: &[f64; 6], b: &[f64; 6]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9);
        let mut arrivals = Arrivals {
            low: f64::NEG_INFINITY,
            high: f64::INFINITY,
            seen: Vec::new(),
        };
        let mut previous: Option<&[f64; 6]> = None;
        for (k, command) in self.commands.iter().enumerate() {
            let new = previous.is_none_or(|p| !same(p, &command.joints_deg));
            previous = Some(&command.joints_deg);
            if !new {
                continue;
            }
            let from = times
                .partition_point(|&t| t < command.sent - SEARCH_BEFORE_S)
                .max(1);
            let to = times.partition_point(|&t| t <= command.replied + SEARCH_AFTER_S);
            let first_showing = (from..to).find(|&i| {
                same(&targets[i], &command.joints_deg)
                    && !same(&targets[i - 1], &command.joints_deg)
            });
            if let Some(i) = first_showing {
                let (after, by) = (clocks[i - 1], clocks[i]);
                arrivals.low = arrivals.low.max(command.sent - by as f64 / 1e3 - 0.0005);
                arrivals.high = arrivals
                    .high
                    .min(command.replied - after as f64 / 1e3 + 0.0005);
                arrivals.seen.push((k, after, by));
            }
        }
        (!arrivals.seen.is_empty()).then_some(arrivals)
    }
}

/// Set points seen arriving at the controller.
struct Arrivals {
    /// Bounds on our clock minus the controller's (s).
    low: f64,
    high: f64,
    /// Each seen set point's index, and the controller's clocks (ms) it arrived after and by.
    seen: Vec<(usize, i64, i64)>,
}

impl Arrivals {
    fn offset(&self) -> f64 {
        0.5 * (self.low + self.high)
    }
}

/// How the run goes.
#[derive(Clone, Debug)]
pub struct RecordOptions {
    /// Move the arm (false: print the plan).
    pub live: bool,
    /// Close the gripper on nothing at this speed (%), after the arm; `None`: leave it.
    pub gripper_speed_percent: Option<u8>,
    /// The gripper's index on the controller (1–8).
    pub gripper_index: u8,
}

impl Default for RecordOptions {
    fn default() -> Self {
        Self {
            live: false,
            gripper_speed_percent: Some(50),
            gripper_index: 1,
        }
    }
}

/// Runs `plan` about the arm's present pose. Dry run: prints it and returns `None`.
pub fn record(
    link: &mut dyn RobotLink,
    filter: &mut SafetyFilter,
    watchdog: &Watchdog,
    plan: &ExcitationPlan,
    options: &RecordOptions,
    interrupt: &AtomicBool,
) -> Result<Option<Recording>> {
    if let Some(s) = options.gripper_speed_percent
        && !(1..=100).contains(&s)
    {
        return Err(DeployError::config(
            "--gripper-speed",
            format!("{s} is outside 1…100 %"),
        ));
    }
    let mut run = Run {
        link,
        watchdog,
        interrupt,
        origin: Instant::now(),
        recording: Recording::default(),
        last_sequence: None,
    };
    let start = run.checked().map_err(stopped_before)?;
    run.recording.start_deg = start.state.joints_deg;
    check_paths(filter, plan, &start.state.joints_deg).map_err(stopped_before)?;
    describe_plan(plan, &start.state.joints_deg, filter, options);
    if !options.live {
        println!("dry run: nothing sent; add --live to move the arm");
        return Ok(None);
    }
    let result = run
        .excite(filter, plan)
        .and_then(|()| match options.gripper_speed_percent {
            Some(speed) => run.gripper(options.gripper_index, speed).map(Some),
            None => Ok(None),
        });
    match result {
        Ok(gripper) => {
            run.recording.gripper = gripper;
            Ok(Some(run.recording))
        }
        Err(fault) => {
            let _ = run.link.send(&RobotCommand::StopMotion);
            let _ = run.link.send(&RobotCommand::ServoMoveEnd);
            Err(DeployError::Other(format!("stopped the arm: {fault}")))
        }
    }
}

fn stopped_before(fault: Fault) -> DeployError {
    DeployError::Other(format!("nothing moved: {fault}"))
}

/// Each joint's whole excursion, both ways, inside the limits, the box and the cell.
fn check_paths(
    filter: &SafetyFilter,
    plan: &ExcitationPlan,
    start: &[f64; 6],
) -> std::result::Result<(), Fault> {
    for &joint in plan.joints() {
        for sign in [1.0, -1.0] {
            let mut to = *start;
            to[joint - 1] += sign * plan.amplitude_deg();
            filter.check_path(start, &to).map_err(|fault| {
                Fault::UnsafeStart(format!(
                    "joint {joint} cannot move {:+.1} deg from here ({fault}); move the arm \
                     nearer the home pose or lower --amplitude-deg",
                    sign * plan.amplitude_deg()
                ))
            })?;
        }
    }
    Ok(())
}

fn describe_plan(
    plan: &ExcitationPlan,
    start: &[f64; 6],
    filter: &SafetyFilter,
    options: &RecordOptions,
) {
    let (speed, acc) = plan.peaks();
    let (cap_v, cap_a, _) = filter.caps();
    println!(
        "sysid plan: joints {:?}, one at a time, ±{:.1} deg about the present pose, at most \
         {speed:.0} deg/s and {acc:.0} deg/s² (the safety caps: {cap_v:.0} deg/s, {cap_a:.0} \
         deg/s²); {:.1} s per joint, {:.0} s in all",
        plan.joints(),
        plan.amplitude_deg(),
        plan.per_joint(),
        plan.duration()
    );
    for &j in plan.joints() {
        println!(
            "  joint {j}: from {:.2} deg, steps to {:+.1} / {:+.1} deg, then a 0.5–4 Hz chirp",
            start[j - 1],
            plan.amplitude_deg(),
            -plan.amplitude_deg()
        );
    }
    if let Some(speed) = options.gripper_speed_percent {
        println!(
            "  gripper {}: open if it is not, close on nothing at {speed} %, open again",
            options.gripper_index
        );
    }
}

struct Run<'a> {
    link: &'a mut dyn RobotLink,
    watchdog: &'a Watchdog,
    interrupt: &'a AtomicBool,
    origin: Instant,
    recording: Recording,
    last_sequence: Option<u64>,
}

impl Run<'_> {
    fn secs(&self, at: Instant) -> f64 {
        at.saturating_duration_since(self.origin).as_secs_f64()
    }

    /// The newest state, judged by the watchdog, and recorded if new.
    fn checked(&mut self) -> std::result::Result<StampedState, Fault> {
        if self.interrupt.load(Ordering::Relaxed) {
            return Err(Fault::Interrupted);
        }
        let s = self
            .link
            .latest_state()
            .map_err(|e| Fault::StreamFailed(e.to_string()))?;
        self.watchdog.check(&s, self.link.now())?;
        if self.last_sequence != Some(s.sequence) {
            self.last_sequence = Some(s.sequence);
            self.recording.states.push(RecordedState {
                received: self.secs(s.received_at),
                clock_ms: s.state.controller_clock_ms,
                joints_deg: s.state.joints_deg,
                servo_target: s.state.last_servo_target_deg,
            });
        }
        Ok(s)
    }

    /// Records states until `t`.
    fn wait_until(&mut self, t: Instant) -> std::result::Result<(), Fault> {
        loop {
            self.checked()?;
            let now = self.link.now();
            if now >= t {
                return Ok(());
            }
            self.link.sleep_until((now + POLL).min(t));
        }
    }

    fn send(&mut self, command: &RobotCommand) -> std::result::Result<(), Fault> {
        self.link.send(command).map_err(|e| Fault::CallFailed {
            call: describe(command),
            message: e.to_string(),
        })
    }

    fn excite(
        &mut self,
        filter: &mut SafetyFilter,
        plan: &ExcitationPlan,
    ) -> std::result::Result<(), Fault> {
        let start = self.recording.start_deg;
        filter.start(&start)?;
        let (_, _, filter_period) = filter.caps();
        let period = filter_period * SEND_STRETCH;
        // A pendant's low override would cap the excitation and read as the drives' lag.
        let percent = filter.speed_override_percent();
        self.send(&RobotCommand::SetSpeed { percent })?;
        self.send(&RobotCommand::ServoMoveStart)?;
        let begun = self.link.now();
        let plan_start = self.secs(begun);
        self.recording.segments = (plan.segments().into_iter())
            .map(|s| Segment {
                start: s.start + plan_start,
                end: s.end + plan_start,
                ..s
            })
            .collect();
        let mut clock = ServoClock::new(begun, Duration::from_secs_f64(period));
        let ticks = (plan.duration() / period).ceil() as u64;
        let mut set_point = start;
        while clock.taken() < ticks {
            self.wait_until(clock.next_due())?;
            let n = clock.take_due(self.link.now(), ticks);
            let offset = plan.offset(clock.taken() as f64 * period);
            let target: [f64; 6] = std::array::from_fn(|j| start[j] + offset[j]);
            for _ in 0..n {
                set_point = filter.next(&target)?;
            }
            self.servo(set_point, period * n as f64)?;
        }
        while let Some(mut next) = filter.brake() {
            self.wait_until(clock.next_due())?;
            let n = clock.take_due(self.link.now(), u64::MAX);
            for _ in 1..n {
                match filter.brake() {
                    Some(p) => next = p,
                    None => break,
                }
            }
            self.servo(next, period * n as f64)?;
        }
        let tail = self.link.now() + Duration::from_secs_f64(TAIL_S);
        self.wait_until(tail)?;
        self.send(&RobotCommand::ServoMoveEnd)
    }

    fn servo(&mut self, joints_deg: [f64; 6], cmd_t: f64) -> std::result::Result<(), Fault> {
        let cmd_t = cmd_t.min(MAX_CMD_T);
        let before = self.link.now();
        self.send(&RobotCommand::ServoJ { joints_deg, cmd_t })?;
        let (sent, replied) = (self.secs(before), self.secs(self.link.now()));
        self.recording.commands.push(SentSetPoint {
            t: 0.5 * (sent + replied),
            sent,
            replied,
            joints_deg,
            cmd_t,
        });
        Ok(())
    }

    /// Closes the gripper on nothing and times it from the reported position; leaves it open.
    fn gripper(&mut self, index: u8, speed: u8) -> std::result::Result<GripperTiming, Fault> {
        let state = self.checked()?.state;
        if !state.gripper_active {
            self.send(&RobotCommand::ActGripper {
                index,
                activate: true,
            })?;
        }
        let move_to = |position_percent| RobotCommand::MoveGripper {
            index,
            position_percent,
            speed_percent: speed,
            force_percent: 50,
            max_time_ms: (GRIPPER_TIMEOUT_S * 1000.0) as u32,
        };
        if state.gripper_position < 95 {
            self.send(&move_to(100))?;
            self.gripper_trace()?;
        }
        let before = self.link.now();
        self.send(&move_to(0))?;
        let sent = 0.5 * (self.secs(before) + self.secs(self.link.now()));
        let trace = self.gripper_trace()?;
        self.send(&move_to(100))?;
        self.gripper_trace()?;
        let first = trace.first().map_or(100.0, |p| p.1);
        let last = trace.last().map_or(first, |p| p.1);
        if (first - last).abs() < 2.0 {
            return Err(Fault::CallFailed {
                call: "MoveGripper".into(),
                message: format!(
                    "the gripper did not move (reported {first:.0} % throughout): is it \
                     activated and configured?"
                ),
            });
        }
        let arrived = (trace.iter())
            .find(|(_, p)| (p - last).abs() <= 1.0)
            .map_or(sent, |(t, _)| *t);
        Ok(GripperTiming {
            speed_percent: speed,
            close_time_s: (arrived - sent).max(0.0),
            final_position_percent: last,
            stalled: last > STALL_PERCENT,
        })
    }

    /// The reported gripper position (time s, %) from now until it has moved and then stood
    /// still for [`GRIPPER_STILL_S`], or the timeout.
    fn gripper_trace(&mut self) -> std::result::Result<Vec<(f64, f64)>, Fault> {
        let begun = self.link.now();
        let mut trace: Vec<(f64, f64)> = Vec::new();
        let mut changed = begun;
        let mut moved = false;
        loop {
            let s = self.checked()?;
            let p = s.state.gripper_position as f64;
            let t = self.secs(s.received_at);
            if trace.last().is_none_or(|&(_, last)| last != p) {
                moved |= !trace.is_empty();
                changed = self.link.now();
                trace.push((t, p));
            }
            let now = self.link.now();
            let still = now.saturating_duration_since(changed).as_secs_f64();
            let elapsed = now.saturating_duration_since(begun).as_secs_f64();
            if (moved && still >= GRIPPER_STILL_S) || elapsed > GRIPPER_TIMEOUT_S {
                return Ok(trace);
            }
            if !moved && s.state.gripper_motion_done && elapsed > 2.0 * GRIPPER_STILL_S {
                return Ok(trace);
            }
            self.link.sleep_until(now + POLL);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A recording on our clock where the controller's clock is `offset` behind: set points
    /// every 8 ms arriving 1 ms into a 3 ms call, frames every 8 ms (phase 3 ms) each on its
    /// way 2-5 ms.
    fn recording(offset: f64, with_targets: bool) -> Recording {
        let mut r = Recording::default();
        let target = |k: usize| [k as f64 * 0.01, 0.0, 0.0, 0.0, 0.0, 0.0];
        let arrivals: Vec<f64> = (0..200).map(|k| 0.1 + k as f64 * 0.008 + 0.001).collect();
        for (k, &a) in arrivals.iter().enumerate() {
            r.commands.push(SentSetPoint {
                t: a + 0.0005,
                sent: a - 0.001,
                replied: a + 0.002,
                joints_deg: target(k),
                cmd_t: 0.008,
            });
        }
        for i in 0..200 {
            let taken = 0.1 + i as f64 * 0.0083 + 0.003;
            let shown = arrivals.iter().rposition(|&a| a <= taken);
            r.states.push(RecordedState {
                received: taken + 0.002 + 0.003 * ((i * 7 % 11) as f64 / 10.0),
                clock_ms: Some(((taken - offset) * 1e3).round() as i64),
                joints_deg: [0.0; 6],
                servo_target: with_targets.then(|| shown.map_or([9.0; 6], target)),
            });
        }
        r
    }

    #[test]
    fn set_points_seen_arriving_align_the_clocks() {
        let offset = 12.345;
        let (found, _) = recording(offset, true).clock_offset().unwrap();
        assert!((found - offset).abs() < 0.0006, "{found} s, not {offset} s");
        // Without the targets, the frames' time on their way (2 ms at least) reads as an
        // offset, and so as the arm's delay.
        let (rough, _) = recording(offset, false).clock_offset().unwrap();
        assert!(rough - offset > 0.0015, "{rough} s");
    }

    #[test]
    fn aligned_set_points_keep_within_their_calls_and_in_order() {
        let r = recording(-3.0, true);
        let aligned = r.aligned();
        for (a, c) in aligned.commands.iter().zip(&r.commands) {
            assert!(c.sent <= a.t && a.t <= c.replied, "{a:?} outside {c:?}");
            assert!((a.t - (c.sent + 0.001)).abs() < 0.0016, "{a:?} for {c:?}");
        }
        assert!(aligned.commands.windows(2).all(|w| w[0].t <= w[1].t));
        // Without the targets nothing moves.
        let plain = recording(-3.0, false);
        assert_eq!(plain.aligned(), plain);
    }
}
