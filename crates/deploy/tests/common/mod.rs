//! Helpers shared by the deploy crate's integration tests.

use fairgrasp_deploy::fairino::{ClientConfig, FairinoClient};
use fairgrasp_deploy::twin::TwinHandle;

/// A client of `twin`'s XML-RPC and CNDE servers on loopback.
pub fn twin_client(twin: &TwinHandle) -> FairinoClient {
    twin_client_with(twin, |_| {})
}

/// The same, with `change` applied to the client's configuration first.
pub fn twin_client_with(
    twin: &TwinHandle,
    change: impl FnOnce(&mut ClientConfig),
) -> FairinoClient {
    let mut config = ClientConfig {
        rpc_port: twin.rpc_addr().port(),
        cnde_port: twin.cnde_addr().port(),
        ..ClientConfig::default()
    };
    change(&mut config);
    FairinoClient::connect("127.0.0.1", &config).unwrap()
}

/// The safety settings for a live deployment on the twin at `speed_scale`, with deadlines a
/// shared host cannot race. The twin is a real-time program on the same two cores as the
/// loop: its 8 ms stream has arrived 76 ms late, and its clock has stood still 51 ms (a CI
/// run), past the 50 ms defaults, while nothing was wrong with the arm's world. Tests that
/// judge grasping or a named fault use these; the watchdog's own deadlines are tested on
/// fixed clocks in `safety::watchdog` and with a stalled stream in `deploy_twin`.
#[allow(dead_code)] // Not every test binary deploys.
pub fn shared_host_safety(speed_scale: f64) -> fairgrasp_deploy::safety::SafetyConfig {
    fairgrasp_deploy::safety::SafetyConfig {
        speed_scale,
        state_deadline_ms: 500.0,
        pose_deadline_ms: 1000.0,
        ..fairgrasp_deploy::safety::SafetyConfig::default()
    }
}

/// Joint speeds under this (deg/s) count as rest: about 1 % of the FR5's top joint speed.
#[allow(dead_code)]
pub const REST_DEG_S: f64 = 2.0;

/// How long the twin's joints take, once the controller's braking has ended, to settle under
/// [`REST_DEG_S`]: they are the training simulator's PD joints, which lag their set points
/// with a time constant near 60 ms (measured: 95 ms after a stop from 9 deg/s streaming,
/// 90 ms after one from the MoveJ home at scale 0.25).
#[allow(dead_code)]
pub const DRIVE_SETTLE_S: f64 = 0.15;

/// Watches the twin's reported joint speeds from now until every one is under
/// [`REST_DEG_S`]: returns the fastest joint speed seen meanwhile (deg/s) and the controller
/// time (s, the twin's clock) of the first report at rest.
#[allow(dead_code)]
pub fn until_rest(twin: &TwinHandle) -> (f64, f64) {
    let until = std::time::Instant::now() + std::time::Duration::from_secs(10);
    let mut fastest = 0.0_f64;
    loop {
        let state = twin.state();
        let top = (state.joint_speeds_deg.iter()).fold(0.0_f64, |m, v| m.max(v.abs()));
        fastest = fastest.max(top);
        if top < REST_DEG_S {
            let clock = state
                .controller_clock_ms
                .expect("the twin stamps its state");
            return (fastest, clock as f64 / 1e3);
        }
        assert!(
            std::time::Instant::now() < until,
            "the arm never came to rest"
        );
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
}

/// Checks a stop from the twin's own records: StopMotion reached it within `deadline_s` of
/// `from` (the twin's clock), and the arm then came to rest within its braking time from the
/// fastest speed seen (at the twin's braking deceleration) plus [`DRIVE_SETTLE_S`].
#[allow(dead_code)]
pub fn check_came_to_rest(twin: &TwinHandle, from: f64, deadline_s: f64, fastest: f64, rest: f64) {
    let calls = twin.calls();
    let stop = (calls.iter())
        .find(|c| c.method == "StopMotion" && c.t >= from)
        .expect("StopMotion reached the twin");
    assert!(
        stop.t - from < deadline_s,
        "StopMotion reached the twin {:.0} ms after the cause",
        (stop.t - from) * 1e3
    );
    let decel = twin.with_controller(|c| c.config().brake_decel_deg_s2);
    let allowed = fastest / decel + DRIVE_SETTLE_S;
    eprintln!(
        "StopMotion {:.1} ms after the cause; at rest {:.1} ms later, from {fastest:.1} deg/s",
        (stop.t - from) * 1e3,
        (rest - stop.t) * 1e3
    );
    assert!(
        rest - stop.t < allowed,
        "at rest {:.0} ms after StopMotion; braking from {fastest:.1} deg/s and settling \
         allow {:.0} ms",
        (rest - stop.t) * 1e3,
        allowed * 1e3
    );
}

/// Samples the twin's fastest joint speed (deg/s) against its controller clock (s) every
/// millisecond until `done`, then for long enough after it for any stop to settle.
#[allow(dead_code)]
pub fn record_speeds(twin: &TwinHandle, done: &std::sync::atomic::AtomicBool) -> Vec<(f64, f64)> {
    let mut trace = Vec::new();
    let mut after = None;
    loop {
        let state = twin.state();
        let top = (state.joint_speeds_deg.iter()).fold(0.0_f64, |m, v| m.max(v.abs()));
        let clock = state
            .controller_clock_ms
            .expect("the twin stamps its state");
        trace.push((clock as f64 / 1e3, top));
        if done.load(std::sync::atomic::Ordering::Relaxed) {
            let since = *after.get_or_insert_with(std::time::Instant::now);
            if since.elapsed() > std::time::Duration::from_millis(500) {
                return trace;
            }
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
}

/// Checks from a [`record_speeds`] trace that the arm came to rest after the twin's last
/// StopMotion within the braking time from the fastest speed seen after it, plus
/// [`DRIVE_SETTLE_S`]: the first sample from which every later one is under [`REST_DEG_S`].
#[allow(dead_code)]
pub fn check_rest_after_stop(twin: &TwinHandle, trace: &[(f64, f64)]) {
    let calls = twin.calls();
    let stop = (calls.iter().rev())
        .find(|c| c.method == "StopMotion")
        .expect("StopMotion reached the twin")
        .t;
    let after: Vec<_> = trace.iter().filter(|(t, _)| *t >= stop).collect();
    assert!(!after.is_empty(), "no joint speeds recorded after the stop");
    let fastest = after.iter().fold(0.0_f64, |m, (_, v)| m.max(*v));
    let moving = after.iter().rposition(|(_, v)| *v >= REST_DEG_S);
    let rest = match moving {
        None => stop,
        Some(i) => {
            assert!(
                i + 1 < after.len(),
                "the arm still moved at the end of the trace"
            );
            after[i + 1].0
        }
    };
    let decel = twin.with_controller(|c| c.config().brake_decel_deg_s2);
    let allowed = fastest / decel + DRIVE_SETTLE_S;
    eprintln!(
        "at rest {:.1} ms after StopMotion, from {fastest:.1} deg/s",
        (rest - stop) * 1e3
    );
    assert!(
        rest - stop < allowed,
        "at rest {:.0} ms after StopMotion; braking from {fastest:.1} deg/s and settling \
         allow {:.0} ms",
        (rest - stop) * 1e3,
        allowed * 1e3
    );
}
