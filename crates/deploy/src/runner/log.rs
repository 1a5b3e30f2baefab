//! The post-mortem log: every command sent and every state received, as JSON lines.

use crate::error::{DeployError, Result};
use crate::robot::{RobotCommand, RobotState};
use serde_json::json;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::time::Instant;

/// JSON lines, one event each: `{"t": seconds since start, "sent": {...}}`,
/// `{"t", "state": {...}}`, `{"t", "step": {...}}`, `{"t", "fault": "..."}`.
pub struct JsonLog {
    out: Option<BufWriter<std::fs::File>>,
    start: Instant,
}

impl JsonLog {
    /// A log written to `path` (created or truncated), or none.
    pub fn create(path: Option<&Path>) -> Result<Self> {
        let out = match path {
            None => None,
            Some(p) => Some(BufWriter::new(std::fs::File::create(p).map_err(|e| {
                DeployError::config(p.display().to_string(), format!("cannot create log: {e}"))
            })?)),
        };
        Ok(Self {
            out,
            start: Instant::now(),
        })
    }

    fn write(&mut self, mut event: serde_json::Value) {
        if let Some(out) = &mut self.out {
            event["t"] = json!(self.start.elapsed().as_secs_f64());
            // A full disk must not stop the arm's safety handling: the write is best effort.
            let _ = writeln!(out, "{event}");
        }
    }

    pub fn sent(&mut self, command: &RobotCommand, result: std::result::Result<(), String>) {
        let mut e = json!({ "sent": command });
        if let Err(message) = result {
            e["error"] = json!(message);
        }
        self.write(e);
    }

    pub fn state(&mut self, sequence: u64, state: &RobotState) {
        self.write(json!({ "state": state, "sequence": sequence }));
    }

    pub fn step(&mut self, episode: u32, step: u32, obs: &[f32], action: &[f32]) {
        self.write(
            json!({ "step": { "episode": episode, "step": step, "obs": obs, "action": action } }),
        );
    }

    pub fn note(&mut self, key: &str, value: serde_json::Value) {
        self.write(json!({ key: value }));
    }

    pub fn flush(&mut self) {
        if let Some(out) = &mut self.out {
            let _ = out.flush();
        }
    }
}

impl Drop for JsonLog {
    fn drop(&mut self) {
        self.flush();
    }
}
