//! The safety layer: between every policy output and the wire, independent of the policy.
//!
//! - [`SafetyConfig`]: the `[safety]` settings (margins, speed and acceleration caps, the TCP
//!   workspace box, the global speed scale, the watchdog's deadline).
//! - [`SafetyFilter`]: turns any requested joint target (NaN and 1e30 included) into a servo
//!   set point that keeps the soft joint limits, the speed and acceleration caps, the TCP's
//!   workspace box and the whole arm's clearance above the table and inside the cell — or
//!   refuses with a [`Fault`], and the arm is stopped.
//! - [`Watchdog`]: judges every state report (age, fault codes, e-stop, safety stop).
//! - [`Fault`]: why the arm was stopped, in words an operator can act on.

mod config;
mod fault;
mod filter;
mod watchdog;

pub use config::SafetyConfig;
pub use fault::Fault;
pub use filter::SafetyFilter;
pub use watchdog::Watchdog;
