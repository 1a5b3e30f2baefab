//! Who sets up and judges each episode: the twin over its own XML-RPC methods, or the
//! operator at a real robot.

use super::EpisodeHost;
use crate::error::{DeployError, Result};
use crate::fairino::xmlrpc::{Value, XmlRpcClient};
use std::io::BufRead;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::Duration;

/// The name a fairgrasp twin answers `TwinInfo` with (how [`TwinHost::detect`] tells it from a
/// real controller).
pub const TWIN_NAME: &str = "fairgrasp-twin";

/// The digital twin: `TwinReset(seed)` places a new object before each episode and
/// `TwinEpisodeResult()` judges it by the task's rule.
pub struct TwinHost {
    rpc: XmlRpcClient,
    seed: u64,
}

impl TwinHost {
    /// Asks the controller at `addr` (`ip:port`) whether it is a fairgrasp twin: `Ok(None)` when
    /// it answers but is not one (a real controller), an error when it does not answer.
    pub fn detect(addr: &str, seed: u64) -> Result<Option<Self>> {
        let rpc = XmlRpcClient::new(addr, Duration::from_secs(2));
        match rpc.call("TwinInfo", &[]) {
            Ok(Value::Array(items)) if items.get(1).and_then(Value::as_str) == Some(TWIN_NAME) => {
                Ok(Some(Self { rpc, seed }))
            }
            Ok(_) => Ok(None),
            // A real controller answers an unknown method with a fault.
            Err(DeployError::Network { .. }) => Err(DeployError::Network {
                call: "TwinInfo".into(),
                addr: addr.into(),
                message: "no answer".into(),
            }),
            Err(_) => Ok(None),
        }
    }
}

impl EpisodeHost for TwinHost {
    fn begin(&mut self, index: u32) -> Result<()> {
        let seed = self.seed + index as u64;
        match self.rpc.call("TwinReset", &[Value::Int(seed as i32)])? {
            Value::Int(0) => Ok(()),
            other => Err(DeployError::Protocol(format!(
                "TwinReset({seed}) answered {other:?}"
            ))),
        }
    }

    fn outcome(&mut self) -> Result<Option<bool>> {
        match self.rpc.call("TwinEpisodeResult", &[])? {
            Value::Array(items) if items.first().and_then(Value::as_i64) == Some(0) => {
                Ok(items.get(1).and_then(Value::as_i64).map(|s| s != 0))
            }
            other => Err(DeployError::Protocol(format!(
                "TwinEpisodeResult answered {other:?}"
            ))),
        }
    }
}

/// A real robot: the operator places the object and presses Enter; nobody judges.
///
/// Only a line counts as Enter: at the end of the input (stdin closed, or deploy run under a
/// pipe or nohup with nothing to read) the episode is refused, so an arm never starts moving
/// without a person having confirmed that the cell is clear. Ctrl-C ends the wait at once:
/// the input is read on its own thread, since a read from a terminal cannot be interrupted.
pub struct OperatorHost {
    lines: Receiver<std::io::Result<usize>>,
    interrupt: Arc<AtomicBool>,
}

/// How often the prompt looks at the interrupt flag.
const PROMPT_POLL: Duration = Duration::from_millis(5);

impl OperatorHost {
    /// The operator at this terminal.
    pub fn stdin(interrupt: Arc<AtomicBool>) -> Self {
        Self::new(std::io::BufReader::new(std::io::stdin()), interrupt)
    }

    /// An operator whose confirmations are the lines of `input`.
    pub fn new(mut input: impl BufRead + Send + 'static, interrupt: Arc<AtomicBool>) -> Self {
        let (lines, received) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            loop {
                let mut line = String::new();
                let read = input.read_line(&mut line);
                let last = !matches!(read, Ok(n) if n > 0);
                if lines.send(read).is_err() || last {
                    return;
                }
            }
        });
        Self {
            lines: received,
            interrupt,
        }
    }
}

impl EpisodeHost for OperatorHost {
    fn begin(&mut self, index: u32) -> Result<()> {
        println!(
            "episode {}: place the object in the workspace, keep clear of the arm, then press \
             Enter (Ctrl-C aborts)",
            index + 1
        );
        let ended = || {
            DeployError::Other(format!(
                "episode {}: the input ended before the operator pressed Enter; end of input \
                 never confirms an episode (run deploy from a terminal)",
                index + 1
            ))
        };
        loop {
            match self.lines.recv_timeout(PROMPT_POLL) {
                Ok(Ok(0)) | Err(RecvTimeoutError::Disconnected) => return Err(ended()),
                Ok(Ok(_)) => return Ok(()),
                Ok(Err(e)) => return Err(e.into()),
                Err(RecvTimeoutError::Timeout) => {
                    if self.interrupt.load(Ordering::Relaxed) {
                        return Err(DeployError::Other(format!(
                            "episode {}: interrupted at the operator's prompt",
                            index + 1
                        )));
                    }
                }
            }
        }
    }

    fn outcome(&mut self) -> Result<Option<bool>> {
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    fn no_interrupt() -> Arc<AtomicBool> {
        Arc::new(AtomicBool::new(false))
    }

    #[test]
    fn only_a_line_confirms_an_episode_and_the_end_of_input_refuses() {
        let mut host = OperatorHost::new(&b"\nready\n"[..], no_interrupt());
        host.begin(0).unwrap();
        host.begin(1).unwrap();
        let err = host.begin(2).unwrap_err().to_string();
        assert!(
            err.contains("episode 3") && err.contains("end of input never confirms"),
            "{err}"
        );
        let err = OperatorHost::new(&b""[..], no_interrupt())
            .begin(0)
            .unwrap_err()
            .to_string();
        assert!(err.contains("episode 1"), "{err}");
    }

    /// An input that never sends a line, like a terminal nobody types at.
    struct Silent;

    impl std::io::Read for Silent {
        fn read(&mut self, _: &mut [u8]) -> std::io::Result<usize> {
            std::thread::sleep(Duration::from_secs(3600));
            Ok(0)
        }
    }

    #[test]
    fn ctrl_c_ends_the_prompt_without_a_line() {
        let interrupt = no_interrupt();
        let mut host = OperatorHost::new(std::io::BufReader::new(Silent), interrupt.clone());
        let raise = {
            let interrupt = interrupt.clone();
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(50));
                interrupt.store(true, Ordering::Relaxed);
                Instant::now()
            })
        };
        let err = host.begin(0).unwrap_err().to_string();
        let raised = raise.join().unwrap();
        assert!(
            err.contains("interrupted at the operator's prompt"),
            "{err}"
        );
        // The prompt looks at the flag every 5 ms; a loaded host may add to it, not 10x.
        assert!(
            raised.elapsed() < Duration::from_millis(50),
            "{:?}",
            raised.elapsed()
        );
    }
}
