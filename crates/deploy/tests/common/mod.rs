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
