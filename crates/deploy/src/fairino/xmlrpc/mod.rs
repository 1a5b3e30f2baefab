//! XML-RPC over HTTP at `/RPC2`, as the FAIRINO controller speaks it and as Python's
//! `xmlrpc.client` (the vendor SDK's transport) sends it.
//!
//! The XML itself is read and written by the `dxr` crate; HTTP by `tiny_http` (server)
//! and `ureq` (client).

pub mod client;
pub mod server;
pub mod value;

pub use client::XmlRpcClient;
pub use server::{Handler, XmlRpcServer};
pub use value::{Fault, Value};
