//! The FAIRINO controller's remote interface, both sides: XML-RPC on TCP 20003 for
//! commands and getters, the CNDE state stream on TCP 20005 (see
//! `fairino-controller.md` and `fairino-cnde.md` in the shared reference).
//!
//! - [`xmlrpc`]: XML-RPC values, a client with timeouts and a threaded server.
//! - [`cnde`]: frames, the state-field table, a streaming server and client.
//! - [`udp`]: the real-time command path on UDP 20007 (`cmdType = 1` servo commands).
//! - [`client::FairinoClient`]: a [`crate::RobotLink`] over them.
//! - [`error_codes`]: what the controller's error codes mean.
//! - [`fr5`]: the FR5's published joint limits and speeds.

pub mod client;
pub mod cnde;
pub mod error_codes;
pub mod fr5;
pub mod udp;
pub mod xmlrpc;

pub use client::{ClientConfig, FairinoClient};
pub use error_codes::error_code_meaning;
