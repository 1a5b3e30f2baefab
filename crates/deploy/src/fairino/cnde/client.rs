//! Our side of the CNDE stream: connect, configure, start, then a thread keeps the newest
//! state. Unlike the vendor SDK it reassembles frames however TCP cuts them, resyncs on
//! garbage, and reports a failed stream instead of reconnecting behind the caller's back.

use super::fields::{Layout, PERIOD_RANGE_MS};
use super::frame::{Frame, FrameDecoder, FrameType, SDK_RECV_SIZE, encode_output_config};
use super::state::decode_state_into;
use crate::error::is_timeout;
use crate::robot::{RobotState, StampedState};
use crate::{DeployError, Result};
use std::io::{ErrorKind, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How often the receive thread looks at its stop flag when no bytes come.
const POLL: Duration = Duration::from_millis(20);
/// Garbage tolerated between two good frames before the stream counts as broken.
const MAX_GARBAGE: u64 = 4 * SDK_RECV_SIZE as u64;
const CALL: &str = "CNDE state stream";

/// How the stream failed.
#[derive(Clone, Debug)]
enum Failure {
    Network(String),
    Protocol(String),
}

#[derive(Default)]
struct Shared {
    latest: Option<StampedState>,
    failure: Option<Failure>,
}

/// A live CNDE subscription. Stops (and tells the controller) on [`CndeClient::close`]
/// or drop.
pub struct CndeClient {
    addr: String,
    shared: Arc<Mutex<Shared>>,
    stopping: Arc<AtomicBool>,
    stream: TcpStream,
    receiver: Option<JoinHandle<()>>,
}

fn lock(shared: &Mutex<Shared>) -> std::sync::MutexGuard<'_, Shared> {
    shared
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

impl CndeClient {
    /// Connects to `addr` ("ip:port"), asks for `names` every `period_ms`, starts the
    /// stream and waits for the first state. The whole handshake is bounded by `timeout`
    /// (plus two periods for the first state).
    pub fn connect(
        addr: &str,
        names: &[String],
        period_ms: u16,
        timeout: Duration,
    ) -> Result<CndeClient> {
        if names.is_empty() {
            return Err(DeployError::config("CNDE state names", "none given"));
        }
        let layout = Layout::new(names)?;
        if !PERIOD_RANGE_MS.contains(&period_ms) {
            return Err(DeployError::config(
                "CNDE period",
                format!("{period_ms} ms is outside 8-1000 ms"),
            ));
        }
        let network = |message: String| DeployError::Network {
            call: CALL.into(),
            addr: addr.into(),
            message,
        };
        let socket_addr: SocketAddr = addr
            .to_socket_addrs()
            .map_err(|e| network(format!("bad address: {e}")))?
            .next()
            .ok_or_else(|| network("the address resolves to nothing".into()))?;
        let deadline = Instant::now() + timeout;
        let mut stream = TcpStream::connect_timeout(&socket_addr, timeout)
            .map_err(|e| network(format!("connect: {e}")))?;
        stream
            .set_nodelay(true)
            .and_then(|()| stream.set_write_timeout(Some(timeout)))
            .map_err(|e| network(e.to_string()))?;

        let max_payload = layout.payload_len.max(SDK_RECV_SIZE);
        let mut decoder = FrameDecoder::new(max_payload);
        let config = Frame::new(
            0,
            FrameType::OutputConfig,
            encode_output_config(period_ms, names),
        );
        send(&mut stream, &config).map_err(|e| network(format!("sending config: {e}")))?;
        loop {
            let reply = read_frame(&mut stream, &mut decoder, deadline)
                .map_err(|e| with_step(e, addr, "waiting for the config reply"))?;
            if reply.kind == FrameType::Message {
                reply.message_status().map_err(|text| {
                    DeployError::Protocol(format!(
                        "{addr}: the controller refused the CNDE output config: {text}"
                    ))
                })?;
                break;
            }
        }
        send(&mut stream, &Frame::new(1, FrameType::OutputStart, vec![]))
            .map_err(|e| network(format!("sending start: {e}")))?;

        // Start is acknowledged by a MESSAGE or by the first DATA frame itself.
        let period = Duration::from_millis(period_ms.into());
        let first_deadline = deadline + 2 * period;
        let mut state = RobotState::default();
        loop {
            let frame = read_frame(&mut stream, &mut decoder, first_deadline)
                .map_err(|e| with_step(e, addr, "waiting for the first state"))?;
            match frame.kind {
                FrameType::Message => frame.message_status().map_err(|text| {
                    DeployError::Protocol(format!(
                        "{addr}: the controller refused to start the CNDE stream: {text}"
                    ))
                })?,
                FrameType::OutputData => {
                    check_len(&frame, &layout).map_err(DeployError::Protocol)?;
                    decode_state_into(&layout, &frame.payload, &mut state);
                    break;
                }
                _ => {}
            }
        }

        let shared = Arc::new(Mutex::new(Shared {
            latest: Some(StampedState {
                state,
                received_at: Instant::now(),
                sequence: 1,
            }),
            failure: None,
        }));
        let stopping = Arc::new(AtomicBool::new(false));
        let receiver = {
            let mut receiver = Receiver {
                stream: stream
                    .try_clone()
                    .map_err(|e| network(format!("clone socket: {e}")))?,
                decoder,
                layout,
                shared: Arc::clone(&shared),
                stopping: Arc::clone(&stopping),
            };
            std::thread::Builder::new()
                .name("cnde-client".into())
                .spawn(move || receiver.run())
                .map_err(|e| network(format!("cannot start the receive thread: {e}")))?
        };
        Ok(CndeClient {
            addr: addr.to_string(),
            shared,
            stopping,
            stream,
            receiver: Some(receiver),
        })
    }

    /// The newest state. An error once the stream has failed (reset, closed, garbage,
    /// or closed by us); a slow or stalled stream is not an error: judge staleness from
    /// `received_at` and `sequence`.
    pub fn latest(&self) -> Result<StampedState> {
        let shared = lock(&self.shared);
        match (&shared.failure, &shared.latest) {
            (Some(Failure::Network(message)), _) => Err(DeployError::Network {
                call: CALL.into(),
                addr: self.addr.clone(),
                message: message.clone(),
            }),
            (Some(Failure::Protocol(message)), _) => Err(DeployError::Protocol(format!(
                "{CALL} from {}: {message}",
                self.addr
            ))),
            (None, Some(latest)) => Ok(latest.clone()),
            (None, None) => Err(DeployError::Network {
                call: CALL.into(),
                addr: self.addr.clone(),
                message: "no state received".into(),
            }),
        }
    }

    /// The controller's address, as given.
    pub fn addr(&self) -> &str {
        &self.addr
    }

    /// Stops the stream (a best-effort STOP, then close) and the receive thread.
    pub fn close(&mut self) {
        if self.stopping.swap(true, Ordering::SeqCst) {
            return;
        }
        let _ = send(
            &mut self.stream,
            &Frame::new(2, FrameType::OutputStop, vec![]),
        );
        let _ = self.stream.shutdown(Shutdown::Both);
        if let Some(receiver) = self.receiver.take() {
            let _ = receiver.join();
        }
        let mut shared = lock(&self.shared);
        shared
            .failure
            .get_or_insert(Failure::Network("closed by this client".into()));
    }
}

impl Drop for CndeClient {
    fn drop(&mut self) {
        self.close();
    }
}

fn with_step(error: Failure, addr: &str, step: &str) -> DeployError {
    match error {
        Failure::Network(message) => DeployError::Network {
            call: format!("{CALL} ({step})"),
            addr: addr.into(),
            message,
        },
        Failure::Protocol(message) => {
            DeployError::Protocol(format!("{CALL} from {addr} ({step}): {message}"))
        }
    }
}

fn send(stream: &mut TcpStream, frame: &Frame) -> std::io::Result<()> {
    let bytes = frame.encode().map_err(std::io::Error::other)?;
    stream.write_all(&bytes)
}

fn check_len(frame: &Frame, layout: &Layout) -> std::result::Result<(), String> {
    // The SDK would fill what fits; a state with stale fields that looks fresh is worse
    // than an error for a safety loop. Extra bytes are ignored, as the SDK does.
    if frame.payload.len() < layout.payload_len {
        return Err(format!(
            "DATA frame of {} payload bytes, the config needs {}",
            frame.payload.len(),
            layout.payload_len
        ));
    }
    Ok(())
}

/// Reads until a whole frame is in, or the deadline passes.
fn read_frame(
    stream: &mut TcpStream,
    decoder: &mut FrameDecoder,
    deadline: Instant,
) -> std::result::Result<Frame, Failure> {
    let mut buf = [0u8; SDK_RECV_SIZE];
    loop {
        if let Some(frame) = decoder.next_frame() {
            return Ok(frame);
        }
        if decoder.discarded() > MAX_GARBAGE {
            return Err(Failure::Protocol(format!(
                "{} bytes of garbage and no frame",
                decoder.discarded()
            )));
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(Failure::Network("timed out".into()));
        }
        stream
            .set_read_timeout(Some(left))
            .map_err(|e| Failure::Network(e.to_string()))?;
        match stream.read(&mut buf) {
            Ok(0) => {
                return Err(Failure::Network(
                    "connection closed by the controller".into(),
                ));
            }
            Ok(n) => decoder.push(&buf[..n]),
            Err(e) if is_timeout(&e) || e.kind() == ErrorKind::Interrupted => {}
            Err(e) => return Err(Failure::Network(describe(&e))),
        }
    }
}

fn describe(e: &std::io::Error) -> String {
    match e.kind() {
        ErrorKind::ConnectionReset => "connection reset by the controller".into(),
        ErrorKind::ConnectionAborted => "connection aborted".into(),
        _ => e.to_string(),
    }
}

struct Receiver {
    stream: TcpStream,
    decoder: FrameDecoder,
    layout: Layout,
    shared: Arc<Mutex<Shared>>,
    stopping: Arc<AtomicBool>,
}

impl Receiver {
    fn run(&mut self) {
        if let Err(failure) = self.receive()
            && !self.stopping.load(Ordering::SeqCst)
        {
            lock(&self.shared).failure.get_or_insert(failure);
        }
    }

    fn receive(&mut self) -> std::result::Result<(), Failure> {
        let mut buf = [0u8; SDK_RECV_SIZE];
        let mut garbage_before = self.decoder.discarded();
        self.stream
            .set_read_timeout(Some(POLL))
            .map_err(|e| Failure::Network(e.to_string()))?;
        while !self.stopping.load(Ordering::SeqCst) {
            while let Some(frame) = self.decoder.next_frame() {
                garbage_before = self.decoder.discarded();
                if frame.kind == FrameType::OutputData {
                    check_len(&frame, &self.layout).map_err(Failure::Protocol)?;
                    self.store(&frame.payload);
                }
                // Messages (the reply to a STOP) and other types carry no state.
            }
            if self.decoder.discarded() - garbage_before > MAX_GARBAGE {
                return Err(Failure::Protocol(format!(
                    "{} bytes of garbage without a valid frame",
                    self.decoder.discarded() - garbage_before
                )));
            }
            match self.stream.read(&mut buf) {
                Ok(0) => {
                    return Err(Failure::Network(
                        "connection closed by the controller".into(),
                    ));
                }
                Ok(n) => self.decoder.push(&buf[..n]),
                Err(e) if is_timeout(&e) || e.kind() == ErrorKind::Interrupted => {}
                Err(e) => return Err(Failure::Network(describe(&e))),
            }
        }
        Ok(())
    }

    fn store(&self, payload: &[u8]) {
        let mut shared = lock(&self.shared);
        let (mut state, sequence) = match &shared.latest {
            Some(latest) => (latest.state.clone(), latest.sequence),
            None => (RobotState::default(), 0),
        };
        decode_state_into(&self.layout, payload, &mut state);
        shared.latest = Some(StampedState {
            state,
            received_at: Instant::now(),
            sequence: sequence + 1,
        });
    }
}
