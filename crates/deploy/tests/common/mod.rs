//! Helpers shared by the deploy crate's integration tests.

use fairgrasp_deploy::fairino::{ClientConfig, FairinoClient};
use fairgrasp_deploy::twin::TwinHandle;

/// A client of `twin`'s XML-RPC and CNDE servers on loopback.
pub fn twin_client(twin: &TwinHandle) -> FairinoClient {
    FairinoClient::connect(
        "127.0.0.1",
        &ClientConfig {
            rpc_port: twin.rpc_addr().port(),
            cnde_port: twin.cnde_addr().port(),
            ..ClientConfig::default()
        },
    )
    .unwrap()
}
