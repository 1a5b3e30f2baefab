//! Every XML-RPC call the twin answered: kept in memory for tests (the newest
//! [`MAX_KEPT`]) and optionally written as JSON lines, one per call, for a post-mortem.

use serde::Serialize;
use std::collections::VecDeque;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;
use std::sync::Mutex;

/// Calls kept in memory: about three hours of 125 Hz ServoJ would not fit, the last few
/// minutes do.
pub const MAX_KEPT: usize = 50_000;

/// One call.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CallRecord {
    /// When the call arrived (s since the twin started).
    pub t: f64,
    /// The XML-RPC method.
    pub method: String,
    /// The parameters, as JSON (ints and doubles as numbers, arrays as arrays).
    pub params: Vec<serde_json::Value>,
    /// The reply, or `{"fault": code, "message": text}`.
    pub reply: serde_json::Value,
    /// How long the answer took, injected delays included (s).
    pub seconds: f64,
}

/// The log.
pub struct CallLog {
    kept: Mutex<VecDeque<CallRecord>>,
    file: Mutex<Option<BufWriter<File>>>,
}

impl CallLog {
    /// A log in memory only, or also written to `path` (created or truncated).
    pub fn new(path: Option<&Path>) -> io::Result<Self> {
        let file = match path {
            Some(p) => Some(BufWriter::new(File::create(p).map_err(|e| {
                io::Error::new(e.kind(), format!("call log {}: {e}", p.display()))
            })?)),
            None => None,
        };
        Ok(Self {
            kept: Mutex::new(VecDeque::new()),
            file: Mutex::new(file),
        })
    }

    /// Keeps a call, dropping the oldest beyond [`MAX_KEPT`], and writes its line to the file,
    /// if any.
    pub fn record(&self, record: CallRecord) {
        if let Some(file) = self.file.lock().expect("call log lock").as_mut() {
            // A full disk must not take the controller down: the line is lost, the call is not.
            if let Ok(line) = serde_json::to_string(&record) {
                let _ = writeln!(file, "{line}").and_then(|_| file.flush());
            }
        }
        let mut kept = self.kept.lock().expect("call log lock");
        if kept.len() >= MAX_KEPT {
            kept.pop_front();
        }
        kept.push_back(record);
    }

    /// The calls kept, oldest first.
    pub fn calls(&self) -> Vec<CallRecord> {
        self.kept
            .lock()
            .expect("call log lock")
            .iter()
            .cloned()
            .collect()
    }

    /// Forgets the calls kept in memory (the file keeps them).
    pub fn clear(&self) {
        self.kept.lock().expect("call log lock").clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_in_memory_and_as_json_lines() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("calls.jsonl");
        let log = CallLog::new(Some(&path)).unwrap();
        for i in 0..3 {
            log.record(CallRecord {
                t: i as f64,
                method: "ServoJ".into(),
                params: vec![serde_json::json!([1.0, 2.0])],
                reply: serde_json::json!(0),
                seconds: 0.001,
            });
        }
        assert_eq!(log.calls().len(), 3);
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<serde_json::Value> = text
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        assert_eq!(lines.len(), 3);
        assert_eq!(lines[2]["method"], "ServoJ");
        assert_eq!(lines[2]["t"], 2.0);
        log.clear();
        assert!(log.calls().is_empty());
        let bad = CallLog::new(Some(&dir.path().join("missing/calls.jsonl")));
        assert!(bad.err().unwrap().to_string().contains("call log"));
    }
}
