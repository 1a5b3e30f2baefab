//! The controller side of the CNDE stream, for the digital twin: accepts any number of
//! (repeated) connections, answers config/start/stop, and streams one DATA frame per
//! period in one write each, as the vendor SDK needs (fairino-cnde.md §2, §7).
//!
//! Each connection has one thread that waits on its socket until the next frame is due,
//! so the period is kept against deadlines (no drift) and requests are answered at once.

use super::fields::{Layout, PERIOD_RANGE_MS, field};
use super::frame::{Frame, FrameDecoder, FrameType, SDK_RECV_SIZE, parse_output_config};
use super::state::encode_state_with;
use crate::error::is_timeout;
use crate::robot::RobotState;
use socket2::SockRef;
use std::io::{self, ErrorKind, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Where the server gets the state to send: called once per DATA frame per connection.
pub type StateSource = Arc<dyn Fn() -> RobotState + Send + Sync>;

/// What happens to one DATA frame that is due (fault injection).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FrameFate {
    /// Sent on time.
    Send,
    /// Left out: the next frame comes a period later.
    Drop,
    /// The state of when it was due, sent this much later; the period restarts after it.
    Late(Duration),
}

/// Decides each due frame's fate (called once per due frame per connection).
pub type FrameFates = Arc<dyn Fn() -> FrameFate + Send + Sync>;

/// The longest a late frame is held.
const MAX_LATE: Duration = Duration::from_secs(1);

/// How long an idle connection thread sleeps before looking at its flags again.
const IDLE_POLL: Duration = Duration::from_millis(10);
/// A client whose receive buffer stays full this long is dropped.
const WRITE_TIMEOUT: Duration = Duration::from_secs(2);

/// Fault injection and bookkeeping shared by the server and whoever drives it.
#[derive(Default)]
pub struct CndeControl {
    /// While set, connections stay open and answer requests but send no DATA frames.
    pub stalled: AtomicBool,
    reset_epoch: AtomicU64,
    live: AtomicUsize,
    fates: Mutex<Option<FrameFates>>,
}

impl std::fmt::Debug for CndeControl {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CndeControl")
            .field("stalled", &self.stalled)
            .field("reset_epoch", &self.reset_epoch)
            .field("live", &self.live)
            .finish_non_exhaustive()
    }
}

impl CndeControl {
    /// Controls with no fault injected, shared.
    pub fn new() -> Arc<Self> {
        Arc::new(Self::default())
    }

    /// Stops (or resumes) the DATA frames of every connection.
    pub fn set_stalled(&self, stalled: bool) {
        self.stalled.store(stalled, Ordering::SeqCst);
    }

    /// Resets every connection open now (RST, as a controller that drops the link):
    /// each notices within a period or 10 ms. Later connections are not affected.
    pub fn reset_all(&self) {
        self.reset_epoch.fetch_add(1, Ordering::SeqCst);
    }

    /// Lets `fates` decide whether each due frame is sent, dropped or held (`None`: every
    /// frame is sent on time).
    pub fn set_fates(&self, fates: Option<FrameFates>) {
        *self.fates.lock().unwrap_or_else(|p| p.into_inner()) = fates;
    }

    fn fate(&self) -> FrameFate {
        let fates = self.fates.lock().unwrap_or_else(|p| p.into_inner()).clone();
        fates.map_or(FrameFate::Send, |f| f())
    }

    /// Connections open now.
    pub fn live_connections(&self) -> usize {
        self.live.load(Ordering::SeqCst)
    }
}

/// A running CNDE server; stops on [`CndeServer::shutdown`] or drop, closing every
/// connection.
pub struct CndeServer {
    local_addr: SocketAddr,
    stopping: Arc<AtomicBool>,
    acceptor: Option<JoinHandle<()>>,
    connections: Arc<Mutex<Vec<JoinHandle<()>>>>,
}

impl CndeServer {
    /// Listens on `bind` (port 0 for any free port).
    pub fn spawn(
        bind: SocketAddr,
        source: StateSource,
        control: Arc<CndeControl>,
    ) -> io::Result<CndeServer> {
        let listener = TcpListener::bind(bind)?;
        let local_addr = listener.local_addr()?;
        let stopping = Arc::new(AtomicBool::new(false));
        let connections = Arc::new(Mutex::new(Vec::new()));
        let acceptor = {
            let stopping = Arc::clone(&stopping);
            let connections = Arc::clone(&connections);
            std::thread::Builder::new()
                .name(format!("cnde-{}", local_addr.port()))
                .spawn(move || accept(listener, source, control, stopping, connections))?
        };
        Ok(CndeServer {
            local_addr,
            stopping,
            acceptor: Some(acceptor),
            connections,
        })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// Stops accepting, closes every connection and waits for their threads.
    pub fn shutdown(&mut self) {
        if self.stopping.swap(true, Ordering::SeqCst) {
            return;
        }
        // Wake the blocking accept with a connection of our own.
        let mut wake = self.local_addr;
        if wake.ip().is_unspecified() {
            wake.set_ip(match wake {
                SocketAddr::V4(_) => std::net::Ipv4Addr::LOCALHOST.into(),
                SocketAddr::V6(_) => std::net::Ipv6Addr::LOCALHOST.into(),
            });
        }
        let _ = TcpStream::connect_timeout(&wake, Duration::from_millis(200));
        if let Some(acceptor) = self.acceptor.take() {
            let _ = acceptor.join();
        }
        let threads = std::mem::take(&mut *lock(&self.connections));
        for thread in threads {
            let _ = thread.join();
        }
    }
}

impl Drop for CndeServer {
    fn drop(&mut self) {
        self.shutdown();
    }
}

fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn accept(
    listener: TcpListener,
    source: StateSource,
    control: Arc<CndeControl>,
    stopping: Arc<AtomicBool>,
    connections: Arc<Mutex<Vec<JoinHandle<()>>>>,
) {
    for stream in listener.incoming() {
        if stopping.load(Ordering::SeqCst) {
            break;
        }
        let Ok(stream) = stream else { continue };
        let connection = Connection {
            stream,
            source: Arc::clone(&source),
            control: Arc::clone(&control),
            stopping: Arc::clone(&stopping),
        };
        let spawned = std::thread::Builder::new()
            .name("cnde-connection".into())
            .spawn(move || connection.run());
        let mut threads = lock(&connections);
        threads.retain(|thread| !thread.is_finished());
        match spawned {
            Ok(thread) => threads.push(thread),
            Err(e) => tracing::warn!("CNDE server: cannot start a connection thread: {e}"),
        }
    }
}

/// What a connection has been asked to send.
struct Output {
    layout: Layout,
    period: Duration,
}

struct Connection {
    stream: TcpStream,
    source: StateSource,
    control: Arc<CndeControl>,
    stopping: Arc<AtomicBool>,
}

/// Why a connection ends.
enum End {
    /// Closed by the client, broken, or the server stops: close normally.
    Close,
    /// Injected reset: abort with RST.
    Reset,
}

impl Connection {
    fn run(mut self) {
        self.control.live.fetch_add(1, Ordering::SeqCst);
        let end = self.serve();
        if matches!(end, End::Reset) {
            // Linger 0 makes the close send RST instead of FIN.
            let _ = SockRef::from(&self.stream).set_linger(Some(Duration::ZERO));
        } else {
            let _ = self.stream.shutdown(Shutdown::Both);
        }
        drop(self.stream);
        self.control.live.fetch_sub(1, Ordering::SeqCst);
    }

    fn serve(&mut self) -> End {
        let epoch = self.control.reset_epoch.load(Ordering::SeqCst);
        // A client that stops reading must not block this thread forever.
        if self.stream.set_nodelay(true).is_err()
            || self.stream.set_write_timeout(Some(WRITE_TIMEOUT)).is_err()
        {
            return End::Close;
        }
        let mut decoder = FrameDecoder::default();
        let mut session = Session::default();
        let mut count: u8 = 0;
        let mut buf = [0u8; SDK_RECV_SIZE];
        loop {
            if self.stopping.load(Ordering::SeqCst) {
                return End::Close;
            }
            if self.control.reset_epoch.load(Ordering::SeqCst) != epoch {
                return End::Reset;
            }
            let now = Instant::now();
            if let Some(output) = session.due(now) {
                if !self.control.stalled.load(Ordering::SeqCst) {
                    let fate = self.control.fate();
                    if fate == FrameFate::Drop {
                        continue;
                    }
                    let payload = encode_state_with(&output.layout, &(self.source)());
                    let frame = Frame::new(count, FrameType::OutputData, payload);
                    if let FrameFate::Late(delay) = fate {
                        std::thread::sleep(delay.min(MAX_LATE));
                    }
                    if self.send(&frame).is_err() {
                        return End::Close;
                    }
                    count = count.wrapping_add(1);
                    if matches!(fate, FrameFate::Late(_)) {
                        // Frames sent back to back would reach the SDK as one recv.
                        session.restart_period(Instant::now());
                    }
                }
                continue;
            }
            // Sleep in the socket until the next frame is due or a request comes.
            // Zero would mean "block forever" to the socket.
            let wait = session.wait(now).max(Duration::from_micros(50));
            if self.stream.set_read_timeout(Some(wait)).is_err() {
                return End::Close;
            }
            match self.stream.read(&mut buf) {
                Ok(0) => return End::Close,
                Ok(n) => decoder.push(&buf[..n]),
                Err(e) if is_timeout(&e) || e.kind() == ErrorKind::Interrupted => continue,
                Err(_) => return End::Close,
            }
            while let Some(request) = decoder.next_frame() {
                let reply = session.reply(&request, count);
                if self.send(&reply).is_err() {
                    return End::Close;
                }
                count = count.wrapping_add(1);
            }
        }
    }

    /// One frame in one write, as the SDK parses each `recv` as one frame.
    fn send(&mut self, frame: &Frame) -> io::Result<()> {
        let bytes = frame.encode().map_err(io::Error::other)?;
        self.stream.write_all(&bytes)
    }
}

/// What a client has asked for, and when its next DATA frame is due.
#[derive(Default)]
struct Session {
    config: Option<Output>,
    /// `Some` while streaming.
    next_due: Option<Instant>,
}

impl Session {
    /// The output to send now, if a frame is due; moves the deadline on by a period
    /// (from the deadline, not from now, so the period does not drift).
    fn due(&mut self, now: Instant) -> Option<&Output> {
        let output = self.config.as_ref()?;
        let next_due = self.next_due.as_mut()?;
        if now < *next_due {
            return None;
        }
        *next_due += output.period;
        if *next_due < now {
            // A whole period behind (a stalled machine): skip, do not burst.
            *next_due = now + output.period;
        }
        Some(output)
    }

    /// The next frame is due a whole period from `now`, if it was due sooner.
    fn restart_period(&mut self, now: Instant) {
        if let (Some(output), Some(next_due)) = (&self.config, self.next_due.as_mut()) {
            *next_due = (*next_due).max(now + output.period);
        }
    }

    /// How long until something is due.
    fn wait(&self, now: Instant) -> Duration {
        self.next_due
            .map_or(IDLE_POLL, |due| due.saturating_duration_since(now))
            .min(IDLE_POLL)
    }

    /// The reply to one request.
    fn reply(&mut self, request: &Frame, count: u8) -> Frame {
        match request.kind {
            FrameType::OutputConfig => match accept_config(&request.payload) {
                Ok(output) => {
                    self.config = Some(output);
                    Frame::message_ok(count)
                }
                Err(text) => Frame::message_error(count, &text),
            },
            FrameType::OutputStart => match &self.config {
                Some(output) => {
                    // The first DATA frame comes a period after the reply: sent
                    // together, the SDK would read both as one frame and drop them.
                    self.next_due
                        .get_or_insert_with(|| Instant::now() + output.period);
                    Frame::message_ok(count)
                }
                None => Frame::message_error(count, "NOT_CONFIGURED"),
            },
            FrameType::OutputStop => {
                self.next_due = None;
                Frame::message_ok(count)
            }
            other => Frame::message_error(count, &format!("UNSUPPORTED type {other:?}")),
        }
    }
}

/// The output a config payload asks for, or the refusal text the SDK understands
/// (`NOT_FOUND <name>` makes it return -18).
fn accept_config(payload: &[u8]) -> Result<Output, String> {
    let (period_ms, names) = parse_output_config(payload).map_err(|e| e.to_string())?;
    if names.is_empty() {
        return Err("NO_STATES".into());
    }
    if let Some(unknown) = names.iter().find(|name| field(name).is_none()) {
        return Err(format!("NOT_FOUND {unknown}"));
    }
    if !PERIOD_RANGE_MS.contains(&period_ms) {
        return Err(format!(
            "PERIOD_OUT_OF_RANGE {period_ms} ms (accepted: {}-{} ms)",
            PERIOD_RANGE_MS.start(),
            PERIOD_RANGE_MS.end()
        ));
    }
    let layout = Layout::new(&names).map_err(|e| e.to_string())?;
    if layout.payload_len + super::frame::OVERHEAD > SDK_RECV_SIZE {
        return Err(format!(
            "TOO_MANY_STATES: {} payload bytes, at most {}",
            layout.payload_len,
            SDK_RECV_SIZE - super::frame::OVERHEAD
        ));
    }
    Ok(Output {
        layout,
        period: Duration::from_millis(period_ms.into()),
    })
}

#[cfg(test)]
mod tests {
    use super::super::fields::default_state_names;
    use super::super::frame::encode_output_config;
    use super::*;

    #[test]
    fn config_checks() {
        assert!(accept_config(&encode_output_config(8, &default_state_names())).is_ok());
        let unknown = vec!["robot_state".to_string(), "bogus".to_string()];
        assert_eq!(
            accept_config(&encode_output_config(8, &unknown))
                .err()
                .unwrap(),
            "NOT_FOUND bogus"
        );
        let names = vec!["robot_state".to_string()];
        assert!(accept_config(&encode_output_config(7, &names)).is_err());
        assert!(accept_config(&encode_output_config(1001, &names)).is_err());
        assert!(accept_config(&encode_output_config(1000, &names)).is_ok());
        assert!(accept_config(&[8, 0]).is_err());
        assert!(accept_config(&[8]).is_err());
        let huge = vec!["cur_lua_file_name".to_string(); 20];
        assert!(accept_config(&encode_output_config(8, &huge)).is_err());
    }
}
