//! Fault injection: what can go wrong between a deploy loop and a controller, on demand.
//!
//! Every fault is a [`FaultCommand`], whoever asks for it: the `fairgrasp twin` flags at start
//! (`--latency-ms`, `--joint-noise-deg`, `--fault NAME=VALUE`), a test through
//! [`crate::twin::TwinHandle::inject`], or another process through the extra XML-RPC method
//! `TwinInjectFault(name, value)`. Names and values (the text form [`FaultCommand::parse`]
//! reads):
//!
//! | name | value | effect |
//! |---|---|---|
//! | `latency_ms` | ms | every XML-RPC reply comes this much later (half before the call acts, half after) |
//! | `stream_latency_ms` | ms | every CNDE frame shows the robot as it was this long ago |
//! | `joint_noise_deg` | deg | Gaussian noise (standard deviation) on the reported joints, CNDE and XML-RPC; the TCP follows them |
//! | `pose_noise_mm` | mm | Gaussian noise on the published object position |
//! | `slow` | `METHOD:MS[:COUNT]`, `*:MS[:COUNT]`, `off` | calls of one method (or every call) delayed by MS, the next COUNT calls or all |
//! | `stall` | 1 / 0 | the CNDE stream stops sending frames (connections stay open) / resumes |
//! | `reset_stream` | any | every CNDE connection is reset (RST) now |
//! | `error` | `MAIN,SUB[,fatal]`, `0` | a controller fault in main_code/sub_code: the arm stops; `fatal` ones `ResetAllError` cannot clear (30); 0 clears |
//! | `estop` | 1 / 0 | the e-stop is pressed (the arm stops, main_code 31) / released |
//! | `safety_stop` | 1 / 0 / `A,B` | safety-stop inputs 0 and 1 (1 sets both): the arm stops, motion calls get 99 |
//! | `latency_jitter_ms` | ms | each reply's latency gets a half-normal extra of this standard deviation (|N(0, σ)|), drawn per call |
//! | `latency_outliers` | `PROB,MS`, `off` | with probability PROB a reply comes MS later still |
//! | `drop_frames` | probability | each CNDE frame is left out with this probability (the next comes a period later) |
//! | `late_frames` | `PROB,MS`, `off` | with probability PROB a CNDE frame is held MS (showing the state of when it was due); the period restarts after it, so frames never bunch |
//! | `tracking` | `DELAY_MS,TAU_MS`, six such pairs (12 numbers, j1 first), `off` | the drives follow the set point after a pure delay, then a first-order lag of time constant TAU; the reported joints and speeds are the drives' (off by default) |
//! | `following_error_deg` | deg, `off` | a set point and actual joint further apart than this is a fault: the arm brakes, main_code 200, sub_code the joint (default 20°) |
//! | `servoj_speed_tolerance` | fraction | a ServoJ step may exceed the joint's top speed by this share before it is refused with 29 (default 0.05) |
//! | `brake_decel_deg_s2` | deg/s² | how hard the set point brakes when the arm stops (default 720) |
//! | `collision_level_n` | N, `off` | a net contact force on the robot above this is a collision: `collision_state` 1, main_code 201, sub_code the joint carrying the link that pressed hardest, the arm brakes (default 400; `--strict` 150) |
//! | `collision` | 1 / 0 | a collision now (`collision_state` 1, main_code 201, sub_code 0, the arm brakes) / its state and fault cleared |
//! | `clear` | any | everything above back to normal, faults cleared |
//!
//! Draws (jitter, outliers, dropped and late frames) come from random streams seeded by the
//! twin's seed, so a run with the same calls in the same order draws the same delays.
//! [`strict`] is the set `fairgrasp twin --strict` turns on.
//!
//! The `Twin…` methods themselves are never delayed, so a test can always reach the twin.

use crate::fairino::cnde::FrameFate;
use fairgrasp_env::random::standard_normal_f64;
use std::fmt;
use std::time::Duration;

pub use fairgrasp_sim::control::JointTracking;

/// The six drives' tracking, j1 first; all zero: the drives are the set point.
pub type TrackingModel = [JointTracking; 6];

/// A share of events and the delay each gets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Occasional {
    /// Chance of each event (0–1).
    pub probability: f64,
    /// The delay each such event gets (ms).
    pub ms: f64,
}

/// Delay of slow replies.
#[derive(Clone, Debug, PartialEq)]
pub struct SlowReplies {
    /// The method to slow down; every method when `None`.
    pub method: Option<String>,
    /// The extra delay of each slowed reply (ms).
    pub delay_ms: f64,
    /// How many more calls to slow down; every one when `None`.
    pub remaining: Option<u32>,
}

/// The faults that stay in force until changed (the one-shot ones act on the controller and
/// the stream directly).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FaultSettings {
    /// Every XML-RPC reply this much later (ms), half before the call acts, half after.
    pub latency_ms: f64,
    /// Every CNDE frame shows the robot as it was this long ago (ms).
    pub stream_latency_ms: f64,
    /// σ of the Gaussian noise on the reported joints (deg).
    pub joint_noise_deg: f64,
    /// σ of the Gaussian noise on the published object position (mm).
    pub pose_noise_mm: f64,
    /// Slowed replies, if any.
    pub slow: Option<SlowReplies>,
    /// The CNDE stream sends no frames (connections stay open).
    pub stalled: bool,
    /// σ of each reply's half-normal extra latency (ms).
    pub latency_jitter_ms: f64,
    /// Replies now and then later still.
    pub latency_outliers: Option<Occasional>,
    /// Probability that a due CNDE frame is left out.
    pub drop_frames: f64,
    /// Due CNDE frames now and then held back.
    pub late_frames: Option<Occasional>,
}

impl FaultSettings {
    /// The extra delay for one call of `method`, counting down a limited slow-down.
    pub fn take_slow_delay(&mut self, method: &str) -> f64 {
        let Some(slow) = &mut self.slow else {
            return 0.0;
        };
        if slow.method.as_deref().is_some_and(|m| m != method) {
            return 0.0;
        }
        let delay = slow.delay_ms;
        if let Some(n) = &mut slow.remaining {
            *n = n.saturating_sub(1);
            if *n == 0 {
                self.slow = None;
            }
        }
        delay
    }

    /// One reply's latency (ms): the base, a half-normal jitter, sometimes an outlier.
    pub fn draw_latency_ms(&self, rng: &mut impl rand::Rng) -> f64 {
        let mut ms = self.latency_ms;
        if self.latency_jitter_ms > 0.0 {
            ms += (self.latency_jitter_ms * standard_normal_f64(rng)).abs();
        }
        if let Some(o) = self.latency_outliers
            && rng.random::<f64>() < o.probability
        {
            ms += o.ms;
        }
        ms
    }

    /// What happens to one CNDE frame that is due.
    pub fn draw_frame_fate(&self, rng: &mut impl rand::Rng) -> FrameFate {
        if self.drop_frames > 0.0 && rng.random::<f64>() < self.drop_frames {
            return FrameFate::Drop;
        }
        match self.late_frames {
            Some(o) if rng.random::<f64>() < o.probability => {
                FrameFate::Late(Duration::from_secs_f64(o.ms / 1000.0))
            }
            _ => FrameFate::Send,
        }
    }
}

/// One fault to inject (see the [module](self) documentation).
#[derive(Clone, Debug, PartialEq)]
pub enum FaultCommand {
    /// `latency_ms`: every XML-RPC reply this much later (ms).
    LatencyMs(f64),
    /// `stream_latency_ms`: every CNDE frame shows the robot as it was this long ago (ms).
    StreamLatencyMs(f64),
    /// `joint_noise_deg`: σ of the Gaussian noise on the reported joints (deg).
    JointNoiseDeg(f64),
    /// `pose_noise_mm`: σ of the Gaussian noise on the published object position (mm).
    PoseNoiseMm(f64),
    /// `slow`: replies to one method, or to every one, delayed; `None` (`off`) ends it.
    Slow(Option<SlowReplies>),
    /// `stall`: the CNDE stream stops sending frames (`true`) or resumes.
    Stall(bool),
    /// `reset_stream`: every CNDE connection reset (RST) now.
    ResetStream,
    /// `error`: a controller fault in `main_code`/`sub_code` (the arm stops), or none.
    Error {
        /// The `main_code`; 0 clears the fault.
        main: i32,
        /// The `sub_code`.
        sub: i32,
        /// `ResetAllError` cannot clear it (it answers 30).
        fatal: bool,
    },
    /// `estop`: the e-stop pressed (`true`: the arm stops, main_code 31) or released.
    Estop(bool),
    /// `safety_stop`: safety-stop inputs 0 and 1 (set: the arm stops, motion calls get 99).
    SafetyStop([bool; 2]),
    /// `latency_jitter_ms`: σ of each reply's half-normal extra latency (ms).
    LatencyJitterMs(f64),
    /// `latency_outliers`: now and then a reply later still; `None` (`off`) ends it.
    LatencyOutliers(Option<Occasional>),
    /// `drop_frames`: probability that a due CNDE frame is left out.
    DropFrames(f64),
    /// `late_frames`: now and then a CNDE frame held back; `None` (`off`) ends it.
    LateFrames(Option<Occasional>),
    /// `tracking`: each drive's delay and lag behind its set point, j1 first.
    Tracking(TrackingModel),
    /// `None`: not checked.
    FollowingErrorDeg(Option<f64>),
    /// `servoj_speed_tolerance`: how far a ServoJ step may exceed the top speed, as a share of it.
    ServojSpeedTolerance(f64),
    /// `brake_decel_deg_s2`: how hard the set point brakes when the arm stops (deg/s²).
    BrakeDecelDegS2(f64),
    /// `None`: detection off.
    CollisionLevelN(Option<f64>),
    /// `collision`: a collision now (`true`), or its state and fault cleared.
    Collision(bool),
    /// `clear`: everything back to normal, faults cleared.
    Clear,
}

/// The fault names [`FaultCommand::parse`] knows.
pub const FAULT_NAMES: [&str; 21] = [
    "latency_ms",
    "stream_latency_ms",
    "joint_noise_deg",
    "pose_noise_mm",
    "slow",
    "stall",
    "reset_stream",
    "error",
    "estop",
    "safety_stop",
    "latency_jitter_ms",
    "latency_outliers",
    "drop_frames",
    "late_frames",
    "tracking",
    "following_error_deg",
    "servoj_speed_tolerance",
    "brake_decel_deg_s2",
    "collision_level_n",
    "collision",
    "clear",
];

/// `fairgrasp twin --strict`: a controller as a real one behaves on a real network. None of
/// these figures is published by FAIRINO; each is a modest choice (docs/deployment.md):
/// drives 8 ms behind their set point with a 15 ms lag, replies jittering by 2 ms with one
/// in 200 a further 30 ms late, one CNDE frame in 100 lost and one in 100 held 20 ms, and
/// collision detection at 150 N.
pub fn strict() -> Vec<FaultCommand> {
    vec![
        FaultCommand::Tracking(
            [JointTracking {
                delay_ms: 8.0,
                tau_ms: 15.0,
            }; 6],
        ),
        FaultCommand::LatencyJitterMs(2.0),
        FaultCommand::LatencyOutliers(Some(Occasional {
            probability: 0.005,
            ms: 30.0,
        })),
        FaultCommand::DropFrames(0.01),
        FaultCommand::LateFrames(Some(Occasional {
            probability: 0.01,
            ms: 20.0,
        })),
        FaultCommand::CollisionLevelN(Some(STRICT_COLLISION_LEVEL_N)),
    ]
}

/// The collision level `--strict` sets (N): the figure common cobot safety settings use for a
/// collaborative stop (chosen: FAIRINO publishes levels, not forces).
pub const STRICT_COLLISION_LEVEL_N: f64 = 150.0;

fn number(name: &str, value: &str, max: f64) -> Result<f64, String> {
    let v: f64 = value
        .trim()
        .parse()
        .map_err(|_| format!("{name}: expected a number, got `{value}`"))?;
    if !(v.is_finite() && (0.0..=max).contains(&v)) {
        return Err(format!("{name}: must be in 0…{max}, got {v}"));
    }
    Ok(v)
}

fn flag(name: &str, value: &str) -> Result<bool, String> {
    match value.trim() {
        "1" | "true" | "on" => Ok(true),
        "0" | "false" | "off" => Ok(false),
        other => Err(format!("{name}: expected 1 or 0, got `{other}`")),
    }
}

fn code(name: &str, value: &str) -> Result<i32, String> {
    value
        .trim()
        .parse()
        .map_err(|_| format!("{name}: expected an integer code, got `{value}`"))
}

impl FaultCommand {
    /// Reads `name` and its `value` as text (the table in the [module](self) documentation).
    pub fn parse(name: &str, value: &str) -> Result<Self, String> {
        Ok(match name.trim() {
            "latency_ms" => Self::LatencyMs(number(name, value, 60_000.0)?),
            "stream_latency_ms" => Self::StreamLatencyMs(number(name, value, 1_000.0)?),
            "joint_noise_deg" => Self::JointNoiseDeg(number(name, value, 10.0)?),
            "pose_noise_mm" => Self::PoseNoiseMm(number(name, value, 100.0)?),
            "slow" => Self::Slow(parse_slow(value)?),
            "stall" => Self::Stall(flag(name, value)?),
            "reset_stream" => Self::ResetStream,
            "error" => {
                let parts: Vec<&str> = value.split(',').map(str::trim).collect();
                match parts.as_slice() {
                    [zero] if code(name, zero)? == 0 => Self::Error {
                        main: 0,
                        sub: 0,
                        fatal: false,
                    },
                    [main, sub] => Self::Error {
                        main: code(name, main)?,
                        sub: code(name, sub)?,
                        fatal: false,
                    },
                    [main, sub, "fatal"] => Self::Error {
                        main: code(name, main)?,
                        sub: code(name, sub)?,
                        fatal: true,
                    },
                    _ => {
                        return Err(format!(
                            "error: expected MAIN,SUB or MAIN,SUB,fatal or 0, got `{value}`"
                        ));
                    }
                }
            }
            "estop" => Self::Estop(flag(name, value)?),
            "safety_stop" => {
                let parts: Vec<&str> = value.split(',').collect();
                match parts.as_slice() {
                    [both] => {
                        let on = flag(name, both)?;
                        Self::SafetyStop([on, on])
                    }
                    [a, b] => Self::SafetyStop([flag(name, a)?, flag(name, b)?]),
                    _ => return Err(format!("safety_stop: expected 1, 0 or A,B, got `{value}`")),
                }
            }
            "latency_jitter_ms" => Self::LatencyJitterMs(number(name, value, 10_000.0)?),
            "latency_outliers" => Self::LatencyOutliers(occasional(name, value, 60_000.0)?),
            "drop_frames" => Self::DropFrames(number(name, value, 1.0)?),
            "late_frames" => Self::LateFrames(occasional(name, value, 1_000.0)?),
            "tracking" => Self::Tracking(parse_tracking(value)?),
            "following_error_deg" => Self::FollowingErrorDeg(match value.trim() {
                "off" => None,
                v => {
                    let deg = number(name, v, 360.0)?;
                    if deg <= 0.0 {
                        return Err(format!("{name}: must be above 0 (or `off`)"));
                    }
                    Some(deg)
                }
            }),
            "servoj_speed_tolerance" => Self::ServojSpeedTolerance(number(name, value, 10.0)?),
            "brake_decel_deg_s2" => {
                let v = number(name, value, 100_000.0)?;
                if v < 1.0 {
                    return Err(format!("{name}: must be at least 1 deg/s², got {v}"));
                }
                Self::BrakeDecelDegS2(v)
            }
            "collision_level_n" => Self::CollisionLevelN(match value.trim() {
                "off" => None,
                v => {
                    let n = number(name, v, 100_000.0)?;
                    if n < 1.0 {
                        return Err(format!("{name}: must be at least 1 N (or `off`), got {n}"));
                    }
                    Some(n)
                }
            }),
            "collision" => Self::Collision(flag(name, value)?),
            "clear" => Self::Clear,
            other => {
                return Err(format!(
                    "unknown fault `{other}`; known: {}",
                    FAULT_NAMES.join(", ")
                ));
            }
        })
    }

    /// Reads `NAME=VALUE` (the `--fault` flag).
    pub fn parse_assignment(text: &str) -> Result<Self, String> {
        let (name, value) = text
            .split_once('=')
            .ok_or_else(|| format!("expected NAME=VALUE, got `{text}`"))?;
        Self::parse(name, value)
    }
}

/// `PROB,MS` or `off`.
fn occasional(name: &str, value: &str, max_ms: f64) -> Result<Option<Occasional>, String> {
    let value = value.trim();
    if value == "off" || value == "0" {
        return Ok(None);
    }
    match value.split(',').collect::<Vec<_>>().as_slice() {
        [p, ms] => Ok(Some(Occasional {
            probability: number(name, p, 1.0)?,
            ms: number(name, ms, max_ms)?,
        })),
        _ => Err(format!("{name}: expected PROB,MS or off, got `{value}`")),
    }
}

/// `DELAY_MS,TAU_MS` for every joint, six such pairs, or `off`.
fn parse_tracking(value: &str) -> Result<TrackingModel, String> {
    let value = value.trim();
    if value == "off" || value == "0" {
        return Ok(TrackingModel::default());
    }
    let numbers = value
        .split(',')
        .map(|v| number("tracking", v, 10_000.0))
        .collect::<Result<Vec<_>, _>>()?;
    let pair = |k: usize| JointTracking {
        delay_ms: numbers[2 * k],
        tau_ms: numbers[2 * k + 1],
    };
    match numbers.len() {
        2 => Ok([pair(0); 6]),
        12 => Ok(std::array::from_fn(pair)),
        n => Err(format!(
            "tracking: expected DELAY_MS,TAU_MS (2 numbers) or six pairs (12), or off; got {n} numbers"
        )),
    }
}

fn parse_slow(value: &str) -> Result<Option<SlowReplies>, String> {
    let value = value.trim();
    if value == "off" || value == "0" {
        return Ok(None);
    }
    let parts: Vec<&str> = value.split(':').collect();
    let (method, delay, count) = match parts.as_slice() {
        [m, d] => (*m, *d, None),
        [m, d, c] => (*m, *d, Some(*c)),
        _ => {
            return Err(format!(
                "slow: expected METHOD:MS[:COUNT], *:MS[:COUNT] or off, got `{value}`"
            ));
        }
    };
    let remaining = match count {
        None => None,
        Some(c) => Some(
            c.parse::<u32>()
                .ok()
                .filter(|&n| n > 0)
                .ok_or_else(|| format!("slow: COUNT must be a positive integer, got `{c}`"))?,
        ),
    };
    Ok(Some(SlowReplies {
        method: (method != "*").then(|| method.to_string()),
        delay_ms: number("slow", delay, 600_000.0)?,
        remaining,
    }))
}

impl fmt::Display for FaultCommand {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::LatencyMs(v) => write!(f, "reply latency {v} ms"),
            Self::StreamLatencyMs(v) => write!(f, "stream latency {v} ms"),
            Self::JointNoiseDeg(v) => write!(f, "joint noise {v}°"),
            Self::PoseNoiseMm(v) => write!(f, "object pose noise {v} mm"),
            Self::Slow(None) => write!(f, "slow replies off"),
            Self::Slow(Some(s)) => write!(
                f,
                "{} delayed {} ms{}",
                s.method.as_deref().unwrap_or("every call"),
                s.delay_ms,
                s.remaining
                    .map(|n| format!(" ({n} calls)"))
                    .unwrap_or_default()
            ),
            Self::Stall(true) => write!(f, "state stream stalled"),
            Self::Stall(false) => write!(f, "state stream resumed"),
            Self::ResetStream => write!(f, "state stream connections reset"),
            Self::Error { main: 0, .. } => write!(f, "fault cleared"),
            Self::Error { main, sub, fatal } => write!(
                f,
                "controller fault main {main} sub {sub}{}",
                if *fatal { " (not resettable)" } else { "" }
            ),
            Self::Estop(true) => write!(f, "e-stop pressed"),
            Self::Estop(false) => write!(f, "e-stop released"),
            Self::SafetyStop(s) => write!(f, "safety stop inputs {}, {}", s[0] as u8, s[1] as u8),
            Self::LatencyJitterMs(v) => write!(f, "reply latency jitter {v} ms"),
            Self::LatencyOutliers(None) => write!(f, "reply latency outliers off"),
            Self::LatencyOutliers(Some(o)) => write!(
                f,
                "reply latency outliers: {} of replies {} ms later",
                o.probability, o.ms
            ),
            Self::DropFrames(p) => write!(f, "state stream drops {p} of its frames"),
            Self::LateFrames(None) => write!(f, "late state frames off"),
            Self::LateFrames(Some(o)) => write!(
                f,
                "state stream holds {} of its frames {} ms",
                o.probability, o.ms
            ),
            Self::Tracking(m) if *m == TrackingModel::default() => write!(f, "drive tracking off"),
            Self::Tracking(m) => {
                write!(f, "drive tracking (delay ms, lag ms):")?;
                for t in m {
                    write!(f, " ({}, {})", t.delay_ms, t.tau_ms)?;
                }
                Ok(())
            }
            Self::FollowingErrorDeg(None) => write!(f, "following error not checked"),
            Self::FollowingErrorDeg(Some(v)) => write!(f, "following error limit {v}°"),
            Self::ServojSpeedTolerance(v) => write!(f, "ServoJ speed tolerance {v}"),
            Self::BrakeDecelDegS2(v) => write!(f, "braking deceleration {v} deg/s²"),
            Self::CollisionLevelN(None) => write!(f, "collision detection off"),
            Self::CollisionLevelN(Some(v)) => write!(f, "collision level {v} N"),
            Self::Collision(true) => write!(f, "collision"),
            Self::Collision(false) => write!(f, "collision cleared"),
            Self::Clear => write!(f, "all faults cleared"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_fault_and_names_mistakes() {
        assert_eq!(
            FaultCommand::parse("latency_ms", "10").unwrap(),
            FaultCommand::LatencyMs(10.0)
        );
        assert_eq!(
            FaultCommand::parse_assignment("error=5,3,fatal").unwrap(),
            FaultCommand::Error {
                main: 5,
                sub: 3,
                fatal: true
            }
        );
        assert_eq!(
            FaultCommand::parse("safety_stop", "0,1").unwrap(),
            FaultCommand::SafetyStop([false, true])
        );
        let slow = FaultCommand::parse("slow", "MoveJ:2000:1").unwrap();
        assert_eq!(
            slow,
            FaultCommand::Slow(Some(SlowReplies {
                method: Some("MoveJ".into()),
                delay_ms: 2000.0,
                remaining: Some(1)
            }))
        );
        assert_eq!(
            FaultCommand::parse("slow", "off").unwrap(),
            FaultCommand::Slow(None)
        );
        for (name, value) in [
            ("latency_ms", "-1"),
            ("joint_noise_deg", "abc"),
            ("stall", "maybe"),
            ("error", "1"),
            ("slow", "MoveJ"),
            ("slow", "*:10:0"),
            ("teleport", "1"),
        ] {
            let e = FaultCommand::parse(name, value).unwrap_err();
            assert!(e.contains(name), "{e}");
        }
        assert!(FaultCommand::parse_assignment("estop").is_err());
    }

    #[test]
    fn parses_the_strict_controller_settings() {
        let pair = |d, t| JointTracking {
            delay_ms: d,
            tau_ms: t,
        };
        assert_eq!(
            FaultCommand::parse("tracking", "8,15").unwrap(),
            FaultCommand::Tracking([pair(8.0, 15.0); 6])
        );
        let six = FaultCommand::parse("tracking", "1,2,3,4,5,6,7,8,9,10,11,12").unwrap();
        let FaultCommand::Tracking(m) = six else {
            panic!("{six:?}")
        };
        assert_eq!((m[0], m[5]), (pair(1.0, 2.0), pair(11.0, 12.0)));
        assert_eq!(
            FaultCommand::parse("tracking", "off").unwrap(),
            FaultCommand::Tracking(TrackingModel::default())
        );
        assert_eq!(
            FaultCommand::parse_assignment("latency_outliers=0.01,40").unwrap(),
            FaultCommand::LatencyOutliers(Some(Occasional {
                probability: 0.01,
                ms: 40.0
            }))
        );
        assert_eq!(
            FaultCommand::parse("following_error_deg", "off").unwrap(),
            FaultCommand::FollowingErrorDeg(None)
        );
        assert_eq!(
            FaultCommand::parse("drop_frames", "0.1").unwrap(),
            FaultCommand::DropFrames(0.1)
        );
        assert_eq!(
            FaultCommand::parse_assignment("collision_level_n=180").unwrap(),
            FaultCommand::CollisionLevelN(Some(180.0))
        );
        assert_eq!(
            FaultCommand::parse("collision_level_n", "off").unwrap(),
            FaultCommand::CollisionLevelN(None)
        );
        assert_eq!(
            FaultCommand::parse("collision", "1").unwrap(),
            FaultCommand::Collision(true)
        );
        assert!(strict().contains(&FaultCommand::CollisionLevelN(Some(150.0))));
        for (name, value) in [
            ("tracking", "1,2,3"),
            ("tracking", "-1,2"),
            ("drop_frames", "1.5"),
            ("late_frames", "0.5"),
            ("latency_outliers", "2,10"),
            ("following_error_deg", "0"),
            ("brake_decel_deg_s2", "0"),
            ("servoj_speed_tolerance", "x"),
            ("collision_level_n", "0"),
            ("collision_level_n", "much"),
            ("collision", "2"),
        ] {
            let e = FaultCommand::parse(name, value).unwrap_err();
            assert!(e.contains(name), "{e}");
        }
        for fault in strict() {
            let text = fault.to_string();
            assert!(!text.is_empty());
        }
    }

    /// Jitter, outliers, dropped and late frames: the same seed draws the same sequence, and
    /// the shares and spread are the ones asked for.
    #[test]
    fn jitter_outliers_and_frame_fates_are_drawn_reproducibly_from_the_seed() {
        use rand::SeedableRng;
        let settings = FaultSettings {
            latency_ms: 10.0,
            latency_jitter_ms: 4.0,
            latency_outliers: Some(Occasional {
                probability: 0.02,
                ms: 100.0,
            }),
            drop_frames: 0.05,
            late_frames: Some(Occasional {
                probability: 0.1,
                ms: 20.0,
            }),
            ..FaultSettings::default()
        };
        let draw = |seed: u64| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let latencies: Vec<f64> = (0..20_000)
                .map(|_| settings.draw_latency_ms(&mut rng))
                .collect();
            let fates: Vec<FrameFate> = (0..20_000)
                .map(|_| settings.draw_frame_fate(&mut rng))
                .collect();
            (latencies, fates)
        };
        let (latencies, fates) = draw(7);
        assert_eq!((latencies.clone(), fates.clone()), draw(7));
        assert_ne!(latencies, draw(8).0);
        let n = latencies.len() as f64;
        assert!(latencies.iter().all(|&l| l >= 10.0));
        let outliers = latencies.iter().filter(|&&l| l >= 100.0).count() as f64 / n;
        assert!((outliers - 0.02).abs() < 0.005, "{outliers}");
        // Half-normal jitter: mean σ√(2/π) ≈ 3.19 ms.
        let usual: Vec<f64> = latencies.iter().copied().filter(|&l| l < 100.0).collect();
        let mean = usual.iter().sum::<f64>() / usual.len() as f64 - 10.0;
        assert!(
            (mean - 4.0 * (2.0 / std::f64::consts::PI).sqrt()).abs() < 0.1,
            "{mean}"
        );
        let dropped = fates.iter().filter(|f| **f == FrameFate::Drop).count() as f64 / n;
        let late = fates
            .iter()
            .filter(|f| **f == FrameFate::Late(Duration::from_millis(20)))
            .count() as f64
            / n;
        assert!((dropped - 0.05).abs() < 0.01, "{dropped}");
        assert!((late - 0.095).abs() < 0.01, "{late}");
        // Nothing set: no draw changes anything.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let calm = FaultSettings::default();
        assert_eq!(calm.draw_latency_ms(&mut rng), 0.0);
        assert_eq!(calm.draw_frame_fate(&mut rng), FrameFate::Send);
    }

    #[test]
    fn slow_replies_count_down_and_match_their_method() {
        let mut s = FaultSettings {
            slow: Some(SlowReplies {
                method: Some("MoveJ".into()),
                delay_ms: 50.0,
                remaining: Some(2),
            }),
            ..FaultSettings::default()
        };
        assert_eq!(s.take_slow_delay("ServoJ"), 0.0);
        assert_eq!(s.take_slow_delay("MoveJ"), 50.0);
        assert_eq!(s.take_slow_delay("MoveJ"), 50.0);
        assert_eq!(s.take_slow_delay("MoveJ"), 0.0);
        assert!(s.slow.is_none());
    }
}
