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
