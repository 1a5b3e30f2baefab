//! The CNDE state stream (TCP 20005): the client configures a period and a list of state
//! names, starts the stream, and the controller sends one DATA frame per period.
//!
//! - [`frame`]: the frame codec and a streaming decoder.
//! - [`fields`]: every state name with its wire type; the vendor SDK's default set.
//! - [`state`]: [`crate::RobotState`] to and from a DATA payload.
//! - [`server`]: the controller side (for the digital twin), with fault injection.
//! - [`client`]: our side, with timeouts, reassembly and failure reporting.

pub mod client;
pub mod fields;
pub mod frame;
pub mod server;
pub mod state;

pub use client::CndeClient;
pub use fields::{DEFAULT_PERIOD_MS, DEFAULT_STATE_NAMES, default_state_names};
pub use frame::{Frame, FrameDecoder, FrameType};
pub use server::{CndeControl, CndeServer, FrameFate, FrameFates, StateSource};
pub use state::{decode_state, encode_state};
