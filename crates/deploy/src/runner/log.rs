//! The post-mortem log: every command sent and every state received, as JSON lines.
//!
//! The servo loop only timestamps an event and queues it; a writer thread of the log's own
//! turns it into JSON and hands it to the kernel within milliseconds (whatever queued up
//! meanwhile goes in the same `write`). So the loop never waits on the disk, and a process
//! killed with SIGKILL leaves everything logged up to its last milliseconds (data the kernel
//! holds survives a process kill; the file is synced to disk only at the end).

use crate::error::{DeployError, Result};
use crate::robot::{RobotCommand, RobotState};
use serde_json::json;
use std::fs::{File, OpenOptions};
use std::io::{ErrorKind, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, OnceLock};
use std::thread::JoinHandle;
use std::time::Instant;

/// The highest number tried for a log beside an earlier one (`run.2.jsonl` … `run.9999.jsonl`).
const MAX_NUMBER: u32 = 9999;

/// A write is issued once this much has queued up, so a backlog goes out in bounded chunks.
const BATCH_BYTES: usize = 64 * 1024;

/// JSON lines, one event each: `{"t": seconds since start, "sent": {...}}`,
/// `{"t", "state": {...}}`, `{"t", "step": {...}}`, `{"t", "fault": "..."}`.
///
/// Logging never blocks on I/O, never fails and never panics: a write that fails is reported
/// once on stderr, counted, and told by [`JsonLog::health`]. Clones log to the same file; the
/// last one dropped waits for everything to be written and syncs the file.
#[derive(Clone)]
pub struct JsonLog {
    inner: Option<Arc<Writer>>,
}

/// What a clone queues.
enum Message {
    Event(Instant, Event),
    /// Answered once every earlier event has been written.
    Flush(Sender<()>),
}

/// An event as the caller gave it; serialised on the writer thread.
enum Event {
    Sent {
        command: RobotCommand,
        error: Option<String>,
    },
    State {
        sequence: u64,
        // Boxed: the queue's messages stay the size of the others.
        state: Box<RobotState>,
    },
    Step {
        episode: u32,
        step: u32,
        obs: Vec<f32>,
        action: Vec<f32>,
    },
    Note {
        key: String,
        value: serde_json::Value,
    },
}

impl Event {
    fn to_json(&self) -> serde_json::Value {
        match self {
            Event::Sent { command, error } => {
                let mut e = json!({ "sent": command });
                if let Some(message) = error {
                    e["error"] = json!(message);
                }
                e
            }
            Event::State { sequence, state } => json!({ "state": state, "sequence": sequence }),
            Event::Step {
                episode,
                step,
                obs,
                action,
            } => json!({
                "step": { "episode": episode, "step": step, "obs": obs, "action": action }
            }),
            Event::Note { key, value } => json!({ key.as_str(): value }),
        }
    }
}

/// The sending end and the writer thread, shared by the clones.
struct Writer {
    path: PathBuf,
    queue: Option<Sender<Message>>,
    thread: Option<JoinHandle<()>>,
    health: Arc<Health>,
}

/// Write failures, as the writer thread saw them.
#[derive(Default)]
struct Health {
    lost: AtomicU64,
    first_error: OnceLock<String>,
}

impl Drop for Writer {
    fn drop(&mut self) {
        // Closing the queue ends the writer once it has written everything.
        self.queue.take();
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl JsonLog {
    /// A log written to `path`, or none. An existing file is never overwritten: the log then
    /// goes to the first free `stem.2.ext`, `stem.3.ext`, … beside it ([`Self::path`] says
    /// which).
    pub fn create(path: Option<&Path>) -> Result<Self> {
        let Some(path) = path else {
            return Ok(Self { inner: None });
        };
        let (file, used) = create_new_numbered(path)?;
        Self::from_file(file, used)
    }

    fn from_file(file: File, path: PathBuf) -> Result<Self> {
        let (queue, received) = channel();
        let health = Arc::new(Health::default());
        let start = Instant::now();
        let thread = {
            let (path, health) = (path.clone(), health.clone());
            std::thread::Builder::new()
                .name("deploy-log".into())
                .spawn(move || write_events(file, &path, start, received, &health))
        }
        .map_err(|e| {
            DeployError::config(
                path.display().to_string(),
                format!("cannot start the log's writer: {e}"),
            )
        })?;
        Ok(Self {
            inner: Some(Arc::new(Writer {
                path,
                queue: Some(queue),
                thread: Some(thread),
                health,
            })),
        })
    }

    /// The file written, if any (not the one asked for when that one existed).
    pub fn path(&self) -> Option<&Path> {
        self.inner.as_ref().map(|w| w.path.as_path())
    }

    /// Why some events are missing from the file, if any are: how many, and the first error.
    /// Complete for what was logged before the last [`Self::flush`].
    pub fn health(&self) -> Option<String> {
        let w = self.inner.as_ref()?;
        let error = w.health.first_error.get()?;
        Some(format!(
            "{} event(s) could not be written to {}: {error}",
            w.health.lost.load(Ordering::Relaxed),
            w.path.display()
        ))
    }

    fn queue(&self, event: impl FnOnce() -> Event) {
        if let Some(w) = &self.inner
            && let Some(queue) = &w.queue
        {
            // Fails only once the writer has gone (it panicked): nothing more can be written.
            let _ = queue.send(Message::Event(Instant::now(), event()));
        }
    }

    /// Logs a command and its outcome: `{"sent": …}`, with `"error"` when it failed.
    pub fn sent(&self, command: &RobotCommand, result: std::result::Result<(), String>) {
        self.queue(|| Event::Sent {
            command: command.clone(),
            error: result.err(),
        });
    }

    /// Logs a state report with its sequence number: `{"state": …, "sequence": n}`.
    pub fn state(&self, sequence: u64, state: &RobotState) {
        self.queue(|| Event::State {
            sequence,
            state: Box::new(state.clone()),
        });
    }

    /// Logs one control step: the observation the policy read and its raw output (`{"step": …}`).
    pub fn step(&self, episode: u32, step: u32, obs: &[f32], action: &[f32]) {
        self.queue(|| Event::Step {
            episode,
            step,
            obs: obs.to_vec(),
            action: action.to_vec(),
        });
    }

    /// Logs `{key: value}` (a fault, an episode's report, a setting).
    pub fn note(&self, key: &str, value: serde_json::Value) {
        self.queue(|| Event::Note {
            key: key.to_string(),
            value,
        });
    }

    /// Waits until everything logged so far (by any clone) has been handed to the kernel.
    pub fn flush(&self) {
        if let Some(w) = &self.inner
            && let Some(queue) = &w.queue
        {
            let (done, finished) = channel();
            if queue.send(Message::Flush(done)).is_ok() {
                let _ = finished.recv();
            }
        }
    }
}

/// Opens `path` if it does not exist, else the first free `stem.N.ext` beside it.
fn create_new_numbered(path: &Path) -> Result<(File, PathBuf)> {
    let fail = |p: &Path, why: String| DeployError::config(p.display().to_string(), why);
    if path.is_dir() {
        return Err(fail(path, "cannot create log: it is a directory".into()));
    }
    let mut candidate = path.to_path_buf();
    let mut n = 1;
    loop {
        match OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&candidate)
        {
            Ok(file) => return Ok((file, candidate)),
            Err(e) if e.kind() == ErrorKind::AlreadyExists && n < MAX_NUMBER => {
                n += 1;
                candidate = numbered(path, n)
                    .ok_or_else(|| fail(path, format!("cannot create log: {e}")))?;
            }
            Err(e) => return Err(fail(&candidate, format!("cannot create log: {e}"))),
        }
    }
}

/// `dir/run.jsonl` → `dir/run.N.jsonl`; `dir/run` → `dir/run.N`.
fn numbered(path: &Path, n: u32) -> Option<PathBuf> {
    let stem = path.file_stem()?.to_string_lossy();
    let name = match path.extension() {
        Some(ext) => format!("{stem}.{n}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{n}"),
    };
    Some(path.with_file_name(name))
}

/// The writer thread: waits for an event, takes whatever else has queued, writes it all in one
/// call, answers the flushes among them; until every clone has gone.
fn write_events(
    mut file: File,
    path: &Path,
    start: Instant,
    received: Receiver<Message>,
    health: &Health,
) {
    let mut batch = Vec::with_capacity(BATCH_BYTES);
    let mut flushes = Vec::new();
    while let Ok(first) = received.recv() {
        let mut events = 0u64;
        let mut next = Some(first);
        while let Some(message) = next {
            match message {
                Message::Event(at, event) => {
                    let mut line = event.to_json();
                    line["t"] = json!(at.saturating_duration_since(start).as_secs_f64());
                    // A Value with string keys always serialises.
                    let _ = serde_json::to_writer(&mut batch, &line);
                    batch.push(b'\n');
                    events += 1;
                }
                Message::Flush(done) => flushes.push(done),
            }
            next = if batch.len() < BATCH_BYTES {
                received.try_recv().ok()
            } else {
                None
            };
        }
        if !batch.is_empty() {
            if let Err(e) = file.write_all(&batch) {
                health.lost.fetch_add(events, Ordering::Relaxed);
                if health.first_error.set(e.to_string()).is_ok() {
                    eprintln!(
                        "log: cannot write to {}: {e} (further failures are only counted)",
                        path.display()
                    );
                }
            }
            batch.clear();
        }
        for done in flushes.drain(..) {
            let _ = done.send(());
        }
    }
    if health.first_error.get().is_none()
        && let Err(e) = file.sync_all()
    {
        eprintln!("log: cannot sync {} to disk: {e}", path.display());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn state(sequence: u64) -> RobotState {
        RobotState {
            joints_deg: [sequence as f64; 6],
            ..RobotState::default()
        }
    }

    fn lines(path: &Path) -> Vec<serde_json::Value> {
        std::fs::read_to_string(path)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect()
    }

    #[test]
    fn a_second_log_at_the_same_path_goes_beside_the_first_and_leaves_it_intact() {
        let dir = tempfile::tempdir().unwrap();
        let asked = dir.path().join("run.jsonl");
        let first = JsonLog::create(Some(&asked)).unwrap();
        first.note("run", json!(1));
        drop(first);
        let before = std::fs::read_to_string(&asked).unwrap();
        assert!(before.contains("\"run\":1"), "{before}");

        let second = JsonLog::create(Some(&asked)).unwrap();
        // Not truncated by a second run at the same path.
        assert_eq!(std::fs::read_to_string(&asked).unwrap(), before);
        assert_eq!(
            second.path(),
            Some(dir.path().join("run.2.jsonl").as_path())
        );
        second.note("run", json!(2));
        let third = JsonLog::create(Some(&asked)).unwrap();
        assert_eq!(third.path(), Some(dir.path().join("run.3.jsonl").as_path()));
        drop((second, third));
        assert_eq!(std::fs::read_to_string(&asked).unwrap(), before);
        assert!(
            std::fs::read_to_string(dir.path().join("run.2.jsonl"))
                .unwrap()
                .contains("\"run\":2")
        );
        // Without an extension the number goes last.
        let bare = dir.path().join("log");
        std::fs::write(&bare, "kept").unwrap();
        let log = JsonLog::create(Some(&bare)).unwrap();
        assert_eq!(log.path(), Some(dir.path().join("log.2").as_path()));
        assert_eq!(JsonLog::create(None).unwrap().path(), None);
    }

    #[test]
    fn a_log_that_cannot_be_created_names_its_path() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("no/such/dir/run.jsonl");
        let e = JsonLog::create(Some(&missing)).err().unwrap().to_string();
        assert!(
            e.contains("no/such/dir/run.jsonl") && e.contains("cannot create log"),
            "{e}"
        );
        let e = JsonLog::create(Some(dir.path())).err().unwrap().to_string();
        assert!(e.contains("directory"), "{e}");
    }

    #[test]
    fn an_event_reaches_the_file_within_a_second_without_a_flush() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.jsonl");
        let log = JsonLog::create(Some(&path)).unwrap();
        log.state(7, &state(7));
        let deadline = Instant::now() + Duration::from_secs(1);
        // The log is alive and was never flushed: only the writer can have put this there.
        while !std::fs::read_to_string(&path).unwrap().ends_with('\n') {
            assert!(Instant::now() < deadline, "nothing written within 1 s");
            std::thread::sleep(Duration::from_millis(1));
        }
        let line = &lines(&path)[0];
        assert_eq!(line["sequence"], 7);
        assert_eq!(line["state"]["joints_deg"][0], 7.0);
        drop(log);
    }

    #[test]
    fn events_from_clones_and_threads_are_all_written_in_the_format_of_the_log() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.jsonl");
        let log = JsonLog::create(Some(&path)).unwrap();
        let servo = RobotCommand::ServoJ {
            joints_deg: [1.0; 6],
            cmd_t: 0.008,
        };
        log.sent(&servo, Ok(()));
        log.sent(&RobotCommand::StopMotion, Err("timed out".into()));
        log.step(0, 3, &[0.5, 1.5], &[-1.0]);
        let other = log.clone();
        std::thread::spawn(move || {
            for i in 0..1000 {
                other.state(i, &state(i));
            }
        })
        .join()
        .unwrap();
        log.note("fault", json!("e-stop"));
        log.flush();
        let text = std::fs::read_to_string(&path).unwrap();
        let first = text.lines().next().unwrap();
        let t = first.split("\"t\":").nth(1).unwrap().trim_end_matches('}');
        assert_eq!(
            first,
            format!(
                r#"{{"sent":{{"call":"ServoJ","cmd_t":0.008,"joints_deg":[1.0,1.0,1.0,1.0,1.0,1.0]}},"t":{t}}}"#
            )
        );
        let all = lines(&path);
        assert_eq!(all.len(), 1004);
        assert_eq!(all[1]["error"], "timed out");
        assert_eq!(all[1]["sent"]["call"], "StopMotion");
        assert_eq!(all[2]["step"]["obs"], json!([0.5, 1.5]));
        assert_eq!(all[2]["step"]["step"], 3);
        let sequences: Vec<u64> = all[3..1003]
            .iter()
            .map(|l| l["sequence"].as_u64().unwrap())
            .collect();
        assert_eq!(sequences, (0..1000).collect::<Vec<_>>());
        assert_eq!(all[1003]["fault"], "e-stop");
        let ts: Vec<f64> = all.iter().map(|l| l["t"].as_f64().unwrap()).collect();
        assert!(ts.windows(2).all(|w| w[0] <= w[1]), "{ts:?}");
        assert!(log.health().is_none());
    }

    #[test]
    fn a_write_error_is_counted_and_told_not_raised() {
        let full = Path::new("/dev/full");
        if !full.exists() {
            eprintln!("skipped: no /dev/full here");
            return;
        }
        let file = OpenOptions::new().write(true).open(full).unwrap();
        let log = JsonLog::from_file(file, full.to_path_buf()).unwrap();
        for i in 0..3 {
            log.state(i, &state(i));
            log.flush();
        }
        let health = log.health().expect("the failures are told");
        assert!(health.starts_with("3 event(s)"), "{health}");
        assert!(health.contains("/dev/full"), "{health}");
        // Logging goes on quietly; dropping the log does not panic either.
        log.note("after", json!(true));
        drop(log);
    }
}
