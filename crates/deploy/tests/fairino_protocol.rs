//! The FAIRINO protocol, both sides, over loopback: the CNDE frame codec against the
//! reference's worked bytes, our CNDE server and client, XML-RPC against our server, a
//! Python `xmlrpc.client` and broken servers, and `FairinoClient`'s exact arguments.

use fairgrasp_deploy::fairino::cnde::fields::{DEFAULT_PAYLOAD_LEN, Layout};
use fairgrasp_deploy::fairino::cnde::frame::{encode_output_config, parse_output_config};
use fairgrasp_deploy::fairino::cnde::{
    CndeClient, CndeControl, CndeServer, DEFAULT_STATE_NAMES, Frame, FrameDecoder, FrameType,
    StateSource, default_state_names, encode_state,
};
use fairgrasp_deploy::fairino::xmlrpc::{Fault, Handler, Value, XmlRpcClient, XmlRpcServer};
use fairgrasp_deploy::fairino::{ClientConfig, FairinoClient};
use fairgrasp_deploy::{DeployError, RobotCommand, RobotLink, RobotState};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

fn loopback() -> SocketAddr {
    "127.0.0.1:0".parse().unwrap()
}

/// Polls `check` until it holds or `limit` passes; whether it held.
fn eventually(limit: Duration, mut check: impl FnMut() -> bool) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        if check() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    check()
}

// ---------------------------------------------------------------- frames

#[test]
fn config_request_matches_the_worked_bytes() {
    let payload = encode_output_config(8, &default_state_names());
    assert_eq!(payload.len(), 1158);
    let bytes = Frame::new(0, FrameType::OutputConfig, payload)
        .encode()
        .unwrap();
    assert_eq!(bytes.len(), 1166);
    assert_eq!(
        &bytes[..8],
        &[0x5A, 0x5A, 0x00, 0x01, 0x86, 0x04, 0x08, 0x00]
    );
    let names = std::str::from_utf8(&bytes[8..bytes.len() - 2]).unwrap();
    assert!(names.starts_with("program_state,robot_state,main_code,"));
    assert!(names.ends_with(",pay_cog,last_servoJ_target"));
    assert_eq!(names.len(), 1156);
    assert_eq!(&bytes[bytes.len() - 2..], &[0xA5, 0xA5]);
    let (period, parsed) = parse_output_config(&bytes[6..bytes.len() - 2]).unwrap();
    assert_eq!((period, parsed.len()), (8, 76));
}

#[test]
fn ok_reply_and_start_match_the_worked_bytes() {
    assert_eq!(
        Frame::message_ok(0).encode().unwrap(),
        [0x5A, 0x5A, 0x00, 0x06, 0x01, 0x00, 0x00, 0xA5, 0xA5]
    );
    assert_eq!(
        Frame::new(1, FrameType::OutputStart, vec![])
            .encode()
            .unwrap(),
        [0x5A, 0x5A, 0x01, 0x02, 0x00, 0x00, 0xA5, 0xA5]
    );
}

#[test]
fn data_frame_matches_the_worked_bytes() {
    let state = RobotState {
        joints_deg: [10.0, -90.0, 0.0, 0.0, 0.0, 0.0],
        robot_state: 1,
        ..RobotState::default()
    };
    let payload = encode_state(&default_state_names(), &state);
    assert_eq!(payload.len(), DEFAULT_PAYLOAD_LEN);
    let bytes = Frame::new(7, FrameType::OutputData, payload)
        .encode()
        .unwrap();
    assert_eq!(bytes.len(), 1326);
    let expected_start: [u8; 33] = [
        0x5A, 0x5A, 0x07, 0x04, 0x26, 0x05, // header
        0x01, 0x01, // program_state, robot_state
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // main_code, sub_code
        0x00, // robot_mode
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x24, 0x40, // j1 = 10.0
        0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x56, 0xC0, // j2 = -90.0
    ];
    assert_eq!(&bytes[..33], &expected_start);
    assert_eq!(&bytes[1324..], &[0xA5, 0xA5]);
}

#[test]
fn default_set_offsets() {
    let layout = Layout::new(&default_state_names()).unwrap();
    assert_eq!(DEFAULT_STATE_NAMES.len(), 76);
    for (name, offset) in [
        ("actual_joint_pos", 11),
        ("actual_TCP_pos", 59),
        ("emergency_stop", 562),
        ("motion_done", 563),
        ("safety_stop0_state", 577),
        ("last_servoJ_target", 1270),
    ] {
        assert_eq!(layout.offset_of(name), Some(offset), "{name}");
    }
    assert_eq!(layout.payload_len, 1318);
}

fn two_frames() -> (Vec<Frame>, Vec<u8>) {
    let state = RobotState {
        joints_deg: [1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        ..RobotState::default()
    };
    let frames = vec![
        Frame::new(
            9,
            FrameType::OutputData,
            encode_state(&default_state_names(), &state),
        ),
        Frame::message_error(10, "NOT_FOUND x"),
    ];
    let mut bytes = frames[0].encode().unwrap();
    bytes.extend(frames[1].encode().unwrap());
    (frames, bytes)
}

#[test]
fn decoder_reassembles_frames_split_anywhere() {
    let (frames, bytes) = two_frames();
    for split in 0..=bytes.len() {
        let mut decoder = FrameDecoder::default();
        let mut got = Vec::new();
        decoder.push(&bytes[..split]);
        got.extend(std::iter::from_fn(|| decoder.next_frame()));
        decoder.push(&bytes[split..]);
        got.extend(std::iter::from_fn(|| decoder.next_frame()));
        assert_eq!(got, frames, "split at {split}");
        assert_eq!(decoder.discarded(), 0);
    }
    // One byte at a time.
    let mut decoder = FrameDecoder::default();
    let mut got = Vec::new();
    for byte in &bytes {
        decoder.push(std::slice::from_ref(byte));
        got.extend(std::iter::from_fn(|| decoder.next_frame()));
    }
    assert_eq!(got, frames);
}

#[test]
fn decoder_resyncs_after_garbage() {
    let (frames, bytes) = two_frames();
    let first_len = frames[0].payload.len() + 8;
    let mut stream = b"junk\x5A\x5A\x00\x63".to_vec(); // a head with a bad type
    stream.extend_from_slice(&bytes[..first_len]);
    stream.extend_from_slice(&[0x5A, 0x5A, 0x00, 0x04, 0x03, 0x00, 1, 2, 3, 0xFF, 0xFF]); // bad tail
    stream.extend_from_slice(&bytes[first_len..]);
    let mut decoder = FrameDecoder::default();
    decoder.push(&stream);
    let got: Vec<Frame> = std::iter::from_fn(|| decoder.next_frame()).collect();
    assert_eq!(got, frames);
    assert_eq!(decoder.discarded(), 8 + 11);
}

// ---------------------------------------------------------------- CNDE stream

struct Twin {
    state: Arc<Mutex<RobotState>>,
    control: Arc<CndeControl>,
    server: CndeServer,
}

fn cnde_twin() -> Twin {
    let state = Arc::new(Mutex::new(RobotState::default()));
    let control = CndeControl::new();
    let source: StateSource = {
        let state = Arc::clone(&state);
        Arc::new(move || state.lock().unwrap().clone())
    };
    let server = CndeServer::spawn(loopback(), source, Arc::clone(&control)).unwrap();
    Twin {
        state,
        control,
        server,
    }
}

fn connect_client(twin: &Twin, period_ms: u16) -> CndeClient {
    CndeClient::connect(
        &twin.server.local_addr().to_string(),
        &default_state_names(),
        period_ms,
        Duration::from_secs(2),
    )
    .unwrap()
}

#[test]
fn cnde_stream_delivers_state_changes() {
    let twin = cnde_twin();
    twin.state.lock().unwrap().joints_deg = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    let client = connect_client(&twin, 8);
    let first = client.latest().unwrap();
    assert_eq!(first.state.joints_deg, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    {
        let mut state = twin.state.lock().unwrap();
        state.joints_deg[0] = -45.5;
        state.emergency_stop = true;
        state.main_code = 14;
    }
    assert!(eventually(Duration::from_secs(2), || {
        let latest = client.latest().unwrap();
        latest.state.joints_deg[0] == -45.5 && latest.state.emergency_stop
    }));
    let later = client.latest().unwrap();
    assert_eq!(later.state.main_code, 14);
    assert!(later.sequence > first.sequence);
    assert!(later.received_at > first.received_at);
    assert_eq!(twin.control.live_connections(), 1);
}

#[test]
fn cnde_period_is_kept_without_bursts() {
    let twin = cnde_twin();
    let client = connect_client(&twin, 50);
    let start = client.latest().unwrap().sequence;
    std::thread::sleep(Duration::from_millis(500));
    let frames = client.latest().unwrap().sequence - start;
    // About 10 frames; generous bounds for a loaded machine.
    assert!(
        (4..=12).contains(&frames),
        "{frames} frames in 500 ms at 50 ms"
    );
}

#[test]
fn stalled_stream_leaves_the_state_old_but_no_error() {
    let twin = cnde_twin();
    let client = connect_client(&twin, 8);
    twin.control.set_stalled(true);
    std::thread::sleep(Duration::from_millis(50)); // let a frame in flight arrive
    let before = client.latest().unwrap();
    std::thread::sleep(Duration::from_millis(150));
    let after = client.latest().unwrap();
    assert_eq!(
        after.sequence, before.sequence,
        "a stalled stream sent frames"
    );
    assert!(after.received_at.elapsed() >= Duration::from_millis(150));
    twin.control.set_stalled(false);
    assert!(eventually(Duration::from_secs(2), || {
        client.latest().unwrap().sequence > before.sequence
    }));
}

#[test]
fn reset_makes_latest_an_error_and_the_server_takes_new_connections() {
    let twin = cnde_twin();
    let client = connect_client(&twin, 8);
    twin.control.reset_all();
    assert!(eventually(Duration::from_secs(2), || client
        .latest()
        .is_err()));
    let err = client.latest().unwrap_err();
    assert!(matches!(err, DeployError::Network { .. }), "{err}");
    assert!(err.to_string().contains("reset"), "{err}");
    // The next connection is not affected by the old reset.
    let again = connect_client(&twin, 8);
    std::thread::sleep(Duration::from_millis(50));
    assert!(again.latest().is_ok());
    assert!(eventually(Duration::from_secs(2), || {
        twin.control.live_connections() == 1
    }));
}

#[test]
fn closed_server_makes_latest_an_error() {
    let mut twin = cnde_twin();
    let client = connect_client(&twin, 8);
    twin.server.shutdown();
    assert!(eventually(Duration::from_secs(2), || client
        .latest()
        .is_err()));
    assert!(client.latest().unwrap_err().to_string().contains("closed"));
}

#[test]
fn unknown_names_and_bad_periods_are_refused() {
    let twin = cnde_twin();
    let addr = twin.server.local_addr().to_string();
    let names = vec!["robot_state".to_string(), "warp_drive".to_string()];
    // Our client refuses before sending.
    let err = CndeClient::connect(&addr, &names, 8, Duration::from_secs(1))
        .err()
        .unwrap();
    assert!(err.to_string().contains("warp_drive"), "{err}");
    // The server refuses as the SDK expects: MESSAGE [1] "NOT_FOUND <name>".
    let mut raw = TcpStream::connect(&addr).unwrap();
    let reply = request(
        &mut raw,
        Frame::new(0, FrameType::OutputConfig, encode_output_config(8, &names)),
    );
    assert_eq!(reply.kind, FrameType::Message);
    assert_eq!(reply.payload[0], 1);
    assert_eq!(&reply.payload[1..], b"NOT_FOUND warp_drive");
    let reply = request(
        &mut raw,
        Frame::new(
            1,
            FrameType::OutputConfig,
            encode_output_config(5, &names[..1]),
        ),
    );
    assert_eq!(reply.payload[0], 1, "period 5 ms accepted");
    let reply = request(&mut raw, Frame::new(2, FrameType::OutputStart, vec![]));
    assert_ne!(reply.payload[0], 0, "start without a config accepted");
}

fn request(stream: &mut TcpStream, frame: Frame) -> Frame {
    stream.write_all(&frame.encode().unwrap()).unwrap();
    read_one(stream, &mut FrameDecoder::default(), |_| true)
}

fn read_one(
    stream: &mut TcpStream,
    decoder: &mut FrameDecoder,
    want: impl Fn(&Frame) -> bool,
) -> Frame {
    stream
        .set_read_timeout(Some(Duration::from_secs(2)))
        .unwrap();
    let mut buf = [0u8; 4096];
    loop {
        while let Some(frame) = decoder.next_frame() {
            if want(&frame) {
                return frame;
            }
        }
        let n = stream.read(&mut buf).expect("a reply in time");
        assert!(n > 0, "connection closed");
        decoder.push(&buf[..n]);
    }
}

#[test]
fn stop_ends_the_stream_and_dead_clients_are_tolerated() {
    let twin = cnde_twin();
    let addr = twin.server.local_addr();
    // A client that configures and dies.
    {
        let mut dying = TcpStream::connect(addr).unwrap();
        let config = Frame::new(
            0,
            FrameType::OutputConfig,
            encode_output_config(8, &default_state_names()),
        );
        dying.write_all(&config.encode().unwrap()).unwrap();
    }
    let mut raw = TcpStream::connect(addr).unwrap();
    let mut decoder = FrameDecoder::default();
    let config = Frame::new(
        0,
        FrameType::OutputConfig,
        encode_output_config(10, &default_state_names()),
    );
    raw.write_all(&config.encode().unwrap()).unwrap();
    assert_eq!(
        read_one(&mut raw, &mut decoder, |_| true),
        Frame::message_ok(0)
    );
    raw.write_all(
        &Frame::new(1, FrameType::OutputStart, vec![])
            .encode()
            .unwrap(),
    )
    .unwrap();
    let ack = read_one(&mut raw, &mut decoder, |_| true);
    assert_eq!(ack.message_status(), Ok(()));
    for _ in 0..3 {
        let data = read_one(&mut raw, &mut decoder, |_| true);
        assert_eq!(data.kind, FrameType::OutputData);
        assert_eq!(data.payload.len(), DEFAULT_PAYLOAD_LEN);
    }
    raw.write_all(
        &Frame::new(2, FrameType::OutputStop, vec![])
            .encode()
            .unwrap(),
    )
    .unwrap();
    let stop_ack = read_one(&mut raw, &mut decoder, |f| f.kind == FrameType::Message);
    assert_eq!(stop_ack.message_status(), Ok(()));
    // Nothing after the STOP's reply.
    raw.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let mut buf = [0u8; 4096];
    match raw.read(&mut buf) {
        Ok(n) => panic!("{n} bytes after STOP"),
        Err(e) => assert!(matches!(
            e.kind(),
            std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
        )),
    }
    assert!(eventually(Duration::from_secs(2), || {
        twin.control.live_connections() == 1
    }));
}

// ---------------------------------------------------------------- XML-RPC

/// Echoes its parameters; `Fail` faults; `Block` waits until `Release` is called.
#[derive(Default)]
struct TestHandler {
    released: Mutex<bool>,
    wake: Condvar,
}

impl Handler for TestHandler {
    fn call(&self, method: &str, params: Vec<Value>) -> Result<Value, Fault> {
        match method {
            "Echo" => Ok(Value::Array(params)),
            "Fail" => Err(Fault::new(42, "the arm is on fire")),
            "Panic" => panic!("handler bug"),
            "Block" => {
                let released = self.released.lock().unwrap();
                let (released, _) = self
                    .wake
                    .wait_timeout_while(released, Duration::from_secs(5), |r| !*r)
                    .unwrap();
                Ok(Value::Bool(*released))
            }
            "Release" => {
                *self.released.lock().unwrap() = true;
                self.wake.notify_all();
                Ok(Value::Int(0))
            }
            other => Err(Fault::new(1, format!("no method {other}"))),
        }
    }
}

fn xml_server() -> XmlRpcServer {
    XmlRpcServer::spawn(loopback(), Arc::new(TestHandler::default())).unwrap()
}

#[test]
fn our_client_against_our_server() {
    let server = xml_server();
    let client = XmlRpcClient::new(&server.local_addr().to_string(), Duration::from_secs(2));
    let params = vec![
        Value::Int(-3),
        Value::Double(0.008),
        Value::doubles(&[1.0, -2.5]),
        Value::from("text & <tags>"),
        Value::Bool(false),
        Value::Array(vec![]),
    ];
    assert_eq!(
        client.call("Echo", &params).unwrap(),
        Value::Array(params.clone())
    );
    assert_eq!(client.call("Echo", &[]).unwrap(), Value::Array(vec![]));
    let err = client.call("Fail", &[]).unwrap_err().to_string();
    assert!(
        err.contains("the arm is on fire") && err.contains("Fail"),
        "{err}"
    );
    // Printing the panic (and a backtrace, where enabled) can take seconds.
    let err = client
        .call_with_timeout("Panic", &[], Duration::from_secs(60))
        .unwrap_err()
        .to_string();
    assert!(err.contains("internal error"), "{err}");
    // The server still answers after a panicking handler.
    assert!(client.call("Echo", &[Value::Int(1)]).is_ok());
}

#[test]
fn a_blocked_call_does_not_block_another() {
    let server = xml_server();
    let addr = server.local_addr().to_string();
    let client = XmlRpcClient::new(&addr, Duration::from_secs(4));
    let blocked = {
        let client = client.clone();
        std::thread::spawn(move || client.call("Block", &[]))
    };
    std::thread::sleep(Duration::from_millis(50));
    // Only a concurrent server can answer this while Block waits.
    client.call("Release", &[]).unwrap();
    assert_eq!(blocked.join().unwrap().unwrap(), Value::Bool(true));
}

#[test]
fn python_xmlrpc_client_talks_to_our_server() {
    if std::process::Command::new("python3")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("note: python3 not found; skipping the Python xmlrpc.client check");
        return;
    }
    let server = xml_server();
    let script = format!(
        r#"
import xmlrpc.client as x
p = x.ServerProxy('http://{addr}')
print(repr(p.Echo(1, 2.5, [1.0, 2.0, 3.0], 'hi', True)))
print(repr(p.Echo([1.0, 2.0, 3.0, 4.0, 5.0, 6.0], [0.0] * 4, 0.0, 0.0, 0.008, 0.0, 0.0, 0)))
try:
    p.Fail()
except x.Fault as f:
    print('fault', f.faultCode, f.faultString)
"#,
        addr = server.local_addr()
    );
    let output = std::process::Command::new("python3")
        .args(["-c", &script])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "python failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines[0], "[1, 2.5, [1.0, 2.0, 3.0], 'hi', True]");
    assert_eq!(
        lines[1],
        "[[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], [0.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.008, 0.0, 0.0, 0]"
    );
    assert_eq!(lines[2], "fault 42 the arm is on fire");
}

/// A TCP server that reads each request and answers with `reply` (or never, if `None`).
fn fake_http_server(reply: Option<&'static [u8]>) -> SocketAddr {
    let listener = TcpListener::bind(loopback()).unwrap();
    let addr = listener.local_addr().unwrap();
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut stream) = stream else { return };
            std::thread::spawn(move || {
                let mut buf = [0u8; 4096];
                let _ = stream.set_read_timeout(Some(Duration::from_millis(200)));
                let _ = stream.read(&mut buf);
                match reply {
                    Some(reply) => {
                        let _ = stream.write_all(reply);
                    }
                    None => std::thread::sleep(Duration::from_secs(10)),
                }
            });
        }
    });
    addr
}

#[test]
fn a_silent_server_times_out_naming_method_and_address() {
    let addr = fake_http_server(None).to_string();
    let timeout = Duration::from_millis(200);
    let client = XmlRpcClient::new(&addr, timeout);
    let start = Instant::now();
    let err = client.call("GetControllerIP", &[]).unwrap_err();
    assert!(start.elapsed() < timeout * 5, "took {:?}", start.elapsed());
    assert!(matches!(err, DeployError::Network { .. }), "{err}");
    let text = err.to_string();
    assert!(
        text.contains("GetControllerIP") && text.contains(&addr),
        "{text}"
    );
}

#[test]
fn nobody_listening_is_a_network_error() {
    let addr = TcpListener::bind(loopback()).unwrap().local_addr().unwrap();
    // The listener is dropped: the port refuses.
    let client = XmlRpcClient::new(&addr.to_string(), Duration::from_millis(500));
    let err = client.call("StopMotion", &[]).unwrap_err();
    assert!(matches!(err, DeployError::Network { .. }), "{err}");
    assert!(err.to_string().contains("StopMotion"));
}

#[test]
fn malformed_replies_are_protocol_errors() {
    let replies: [&'static [u8]; 4] = [
        b"HTTP/1.1 200 OK\r\nContent-Length: 5\r\nConnection: close\r\n\r\nhello",
        b"HTTP/1.1 200 OK\r\nContent-Length: 27\r\nConnection: close\r\n\r\n<methodResponse><params>oops",
        b"HTTP/1.1 500 Internal Server Error\r\nContent-Length: 4\r\nConnection: close\r\n\r\nboom",
        b"NONSENSE/9 what\r\n\r\n",
    ];
    for reply in replies {
        let addr = fake_http_server(Some(reply)).to_string();
        let client = XmlRpcClient::new(&addr, Duration::from_millis(500));
        let err = client
            .call("GetActualTCPPose", &[Value::Int(1)])
            .unwrap_err();
        assert!(
            matches!(err, DeployError::Protocol(_)),
            "{:?} gave {err:?}",
            String::from_utf8_lossy(reply)
        );
        assert!(err.to_string().contains("GetActualTCPPose"), "{err}");
    }
}

// ---------------------------------------------------------------- FairinoClient

/// A controller stand-in: records every call and answers with canned replies.
struct FakeController {
    calls: Mutex<Vec<(String, Vec<Value>)>>,
    command_code: AtomicI32,
    /// When set, MoveJ waits for a StopMotion (5 s at most, then answers 76).
    moves_wait_for_stop: AtomicBool,
    move_started: AtomicBool,
    stopped: Mutex<bool>,
    wake: Condvar,
}

impl Handler for FakeController {
    fn call(&self, method: &str, params: Vec<Value>) -> Result<Value, Fault> {
        self.calls
            .lock()
            .unwrap()
            .push((method.to_string(), params));
        let pose = |err: i32| {
            let mut items = vec![Value::Int(err)];
            items.extend([100.0, 200.0, 300.0, 180.0, 0.0, 90.0].map(Value::Double));
            Value::Array(items)
        };
        Ok(match method {
            "GetControllerIP" => Value::Array(vec![Value::Int(0), Value::from("192.168.58.2")]),
            "GetForwardKin" | "GetActualTCPPose" => pose(0),
            "GetActualJointPosDegree" => {
                let mut items = vec![Value::Int(0)];
                items.extend([1.0, 2.0, 3.0, 4.0, 5.0, 6.0].map(Value::Double));
                Value::Array(items)
            }
            "MoveJ" if self.moves_wait_for_stop.load(Ordering::SeqCst) => {
                self.move_started.store(true, Ordering::SeqCst);
                let stopped = self.stopped.lock().unwrap();
                let (stopped, _) = self
                    .wake
                    .wait_timeout_while(stopped, Duration::from_secs(5), |s| !*s)
                    .unwrap();
                Value::Int(if *stopped { 0 } else { 76 })
            }
            "StopMotion" => {
                *self.stopped.lock().unwrap() = true;
                self.wake.notify_all();
                Value::Int(self.command_code.load(Ordering::SeqCst))
            }
            _ => Value::Int(self.command_code.load(Ordering::SeqCst)),
        })
    }
}

struct Controller {
    handler: Arc<FakeController>,
    _rpc: XmlRpcServer,
    twin: Twin,
    config: ClientConfig,
}

fn controller() -> Controller {
    let handler = Arc::new(FakeController {
        calls: Mutex::new(Vec::new()),
        command_code: AtomicI32::new(0),
        moves_wait_for_stop: AtomicBool::new(false),
        move_started: AtomicBool::new(false),
        stopped: Mutex::new(false),
        wake: Condvar::new(),
    });
    let rpc = XmlRpcServer::spawn(loopback(), handler.clone()).unwrap();
    let twin = cnde_twin();
    let config = ClientConfig {
        rpc_port: rpc.local_addr().port(),
        cnde_port: twin.server.local_addr().port(),
        ..ClientConfig::default()
    };
    Controller {
        handler,
        _rpc: rpc,
        twin,
        config,
    }
}

impl Controller {
    fn take_calls(&self) -> Vec<(String, Vec<Value>)> {
        std::mem::take(&mut *self.handler.calls.lock().unwrap())
    }
}

fn types(params: &[Value]) -> Vec<&'static str> {
    params.iter().map(Value::type_name).collect()
}

#[test]
fn fairino_client_sends_the_sdk_arguments() {
    let robot = controller();
    let mut client = FairinoClient::connect("127.0.0.1", &robot.config).unwrap();
    let connect_calls = robot.take_calls();
    assert_eq!(connect_calls, vec![("GetControllerIP".to_string(), vec![])]);

    let joints = [10.0, -90.0, 90.0, 0.0, 45.0, 0.0];
    client
        .send(&RobotCommand::MoveJ {
            joints_deg: joints,
            speed_percent: 20.0,
            acc_percent: 0.0,
        })
        .unwrap();
    let calls = robot.take_calls();
    assert_eq!(calls.len(), 2);
    assert_eq!(
        calls[0],
        ("GetForwardKin".to_string(), vec![Value::doubles(&joints)])
    );
    let (method, params) = &calls[1];
    assert_eq!(method, "MoveJ");
    assert_eq!(
        types(params),
        [
            "array", "array", "int", "int", "double", "double", "double", "array", "double", "int",
            "array"
        ]
    );
    assert_eq!(params[0], Value::doubles(&joints));
    assert_eq!(
        params[1],
        Value::doubles(&[100.0, 200.0, 300.0, 180.0, 0.0, 90.0])
    );
    assert_eq!(params[4], Value::Double(20.0));
    assert_eq!(params[6], Value::Double(100.0));
    assert_eq!(params[7], Value::doubles(&[0.0; 4]));
    assert_eq!(params[8], Value::Double(-1.0));
    assert_eq!(params[10], Value::doubles(&[0.0; 6]));

    client
        .send(&RobotCommand::ServoJ {
            joints_deg: joints,
            cmd_t: 0.008,
        })
        .unwrap();
    let calls = robot.take_calls();
    assert_eq!(calls[0].0, "ServoJ");
    assert_eq!(
        calls[0].1,
        vec![
            Value::doubles(&joints),
            Value::doubles(&[0.0; 4]),
            Value::Double(0.0),
            Value::Double(0.0),
            Value::Double(0.008),
            Value::Double(0.0),
            Value::Double(0.0),
            Value::Int(0),
        ]
    );

    client
        .send(&RobotCommand::MoveGripper {
            index: 1,
            position_percent: 30,
            speed_percent: 50,
            force_percent: 40,
            max_time_ms: 5000,
        })
        .unwrap();
    let calls = robot.take_calls();
    assert_eq!(calls[0].0, "MoveGripper");
    assert_eq!(
        calls[0].1,
        [1, 30, 50, 40, 5000, 1, 0]
            .map(Value::Int)
            .into_iter()
            .chain([Value::Double(0.0), Value::Int(0), Value::Int(0)])
            .collect::<Vec<_>>()
    );

    for (command, expected) in [
        (
            RobotCommand::ActGripper {
                index: 1,
                activate: true,
            },
            vec![Value::Int(1), Value::Int(1)],
        ),
        (RobotCommand::SetSpeed { percent: 30 }, vec![Value::Int(30)]),
        (
            RobotCommand::RobotEnable { enable: true },
            vec![Value::Int(1)],
        ),
        (RobotCommand::Mode { mode: 0 }, vec![Value::Int(0)]),
        (RobotCommand::ServoMoveStart, vec![]),
        (RobotCommand::ServoMoveEnd, vec![]),
        (RobotCommand::StopMotion, vec![]),
        (RobotCommand::ResetAllError, vec![]),
    ] {
        client.send(&command).unwrap();
        assert_eq!(
            robot.take_calls(),
            vec![(command.method().to_string(), expected)],
            "{command:?}"
        );
    }
}

#[test]
fn fairino_client_getters_and_state() {
    let robot = controller();
    robot.twin.state.lock().unwrap().joints_deg = [7.0; 6];
    let client = FairinoClient::connect("127.0.0.1", &robot.config).unwrap();
    assert_eq!(client.joints_deg().unwrap(), [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    assert_eq!(
        client.tcp_pose().unwrap(),
        [100.0, 200.0, 300.0, 180.0, 0.0, 90.0]
    );
    assert_eq!(client.forward_kin(&[0.0; 6]).unwrap()[2], 300.0);
    assert_eq!(client.controller_ip().unwrap(), "192.168.58.2");
    assert_eq!(client.latest_state().unwrap().state.joints_deg, [7.0; 6]);
    assert_eq!(
        client.call_raw("Anything", &[Value::Int(3)]).unwrap(),
        Value::Int(0)
    );
    let calls = robot.take_calls();
    assert_eq!(
        calls[1],
        ("GetActualJointPosDegree".to_string(), vec![Value::Int(1)])
    );
    assert_eq!(
        calls[2],
        ("GetActualTCPPose".to_string(), vec![Value::Int(1)])
    );
}

#[test]
fn fairino_client_reports_controller_codes_and_refuses_unsafe_motion() {
    let robot = controller();
    let mut client = FairinoClient::connect("127.0.0.1", &robot.config).unwrap();
    robot.handler.command_code.store(14, Ordering::SeqCst);
    let err = client.send(&RobotCommand::StopMotion).unwrap_err();
    match &err {
        DeployError::Controller {
            call,
            code,
            meaning,
        } => {
            assert_eq!((call.as_str(), *code), ("StopMotion", 14));
            assert_eq!(meaning, "execution failed");
        }
        other => panic!("{other:?}"),
    }
    robot.handler.command_code.store(0, Ordering::SeqCst);
    robot.take_calls();

    // Non-finite values never leave the client.
    let err = client
        .send(&RobotCommand::ServoJ {
            joints_deg: [0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0],
            cmd_t: 0.008,
        })
        .unwrap_err();
    assert!(err.to_string().contains("non-finite"), "{err}");

    // A reported safety stop refuses motion with 99, as the SDK does, without a call.
    robot.twin.state.lock().unwrap().safety_stop = [true, false];
    assert!(eventually(Duration::from_secs(2), || {
        client.state().unwrap().state.safety_stop[0]
    }));
    let err = client
        .send(&RobotCommand::ServoJ {
            joints_deg: [0.0; 6],
            cmd_t: 0.008,
        })
        .unwrap_err();
    assert!(
        matches!(err, DeployError::Controller { code: 99, .. }),
        "{err}"
    );
    client.send(&RobotCommand::StopMotion).unwrap();
    assert_eq!(robot.take_calls(), vec![("StopMotion".to_string(), vec![])]);
}

#[test]
fn stop_motion_goes_through_while_move_j_blocks() {
    let robot = controller();
    robot
        .handler
        .moves_wait_for_stop
        .store(true, Ordering::SeqCst);
    let client = FairinoClient::connect("127.0.0.1", &robot.config).unwrap();
    let stopper = client.rpc().clone();
    let mover = std::thread::spawn(move || {
        client.send_command(&RobotCommand::MoveJ {
            joints_deg: [0.0; 6],
            speed_percent: 10.0,
            acc_percent: 0.0,
        })
    });
    assert!(eventually(Duration::from_secs(2), || {
        robot.handler.move_started.load(Ordering::SeqCst)
    }));
    assert_eq!(stopper.call("StopMotion", &[]).unwrap(), Value::Int(0));
    // MoveJ answers 0 only if the StopMotion reached the controller while it waited.
    mover.join().unwrap().unwrap();
}

#[test]
fn connect_fails_cleanly_without_a_controller() {
    let free = TcpListener::bind(loopback())
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let config = ClientConfig {
        rpc_port: free,
        cnde_port: free,
        connect_timeout: Duration::from_millis(300),
        ..ClientConfig::default()
    };
    let err = FairinoClient::connect("127.0.0.1", &config).err().unwrap();
    assert!(matches!(err, DeployError::Network { .. }), "{err}");
    assert!(FairinoClient::connect("", &config).is_err());
}

// ---------------------------------------------------------------- CNDE client vs. raw servers

/// A one-connection CNDE server that answers config and start, then hands the socket to
/// `script`.
fn scripted_cnde_server(script: impl FnOnce(TcpStream) + Send + 'static) -> String {
    let listener = TcpListener::bind(loopback()).unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    std::thread::spawn(move || {
        let (mut stream, _) = listener.accept().unwrap();
        let mut decoder = FrameDecoder::default();
        for _ in 0..2 {
            read_one(&mut stream, &mut decoder, |_| true);
            stream
                .write_all(&Frame::message_ok(0).encode().unwrap())
                .unwrap();
        }
        script(stream);
    });
    addr
}

fn data_frame(j1: f64) -> Vec<u8> {
    let state = RobotState {
        joints_deg: [j1, 0.0, 0.0, 0.0, 0.0, 0.0],
        ..RobotState::default()
    };
    Frame::new(
        0,
        FrameType::OutputData,
        encode_state(&default_state_names(), &state),
    )
    .encode()
    .unwrap()
}

#[test]
fn cnde_client_reassembles_merged_and_split_frames() {
    let addr = scripted_cnde_server(|mut stream| {
        let pause = || std::thread::sleep(Duration::from_millis(20));
        stream.write_all(&data_frame(1.0)).unwrap();
        pause();
        // Two frames in one write, then one in three pieces, garbage in between.
        let mut merged = data_frame(2.0);
        merged.extend(data_frame(3.0));
        merged.extend(b"\x00\x01junk\x5A");
        stream.write_all(&merged).unwrap();
        pause();
        let split = data_frame(4.0);
        for piece in [&split[..5], &split[5..700], &split[700..]] {
            stream.write_all(piece).unwrap();
            pause();
        }
        std::thread::sleep(Duration::from_secs(3));
    });
    let client =
        CndeClient::connect(&addr, &default_state_names(), 8, Duration::from_secs(2)).unwrap();
    assert!(eventually(Duration::from_secs(2), || {
        client.latest().unwrap().state.joints_deg[0] == 4.0
    }));
    // 1 + 2 merged + 1 split: every frame decoded, the garbage skipped.
    assert_eq!(client.latest().unwrap().sequence, 4);
}

#[test]
fn cnde_client_fails_on_endless_garbage_and_short_frames() {
    let addr = scripted_cnde_server(|mut stream| {
        stream.write_all(&data_frame(1.0)).unwrap();
        for _ in 0..10 {
            if stream.write_all(&[0x11; 4096]).is_err() {
                return;
            }
        }
        std::thread::sleep(Duration::from_secs(3));
    });
    let client =
        CndeClient::connect(&addr, &default_state_names(), 8, Duration::from_secs(2)).unwrap();
    assert!(eventually(Duration::from_secs(2), || client
        .latest()
        .is_err()));
    let err = client.latest().unwrap_err();
    assert!(matches!(err, DeployError::Protocol(_)), "{err}");
    assert!(err.to_string().contains("garbage"), "{err}");

    let addr = scripted_cnde_server(|mut stream| {
        stream.write_all(&data_frame(1.0)).unwrap();
        let short = Frame::new(0, FrameType::OutputData, vec![1, 1, 0, 0]);
        stream.write_all(&short.encode().unwrap()).unwrap();
        std::thread::sleep(Duration::from_secs(3));
    });
    let client =
        CndeClient::connect(&addr, &default_state_names(), 8, Duration::from_secs(2)).unwrap();
    assert!(eventually(Duration::from_secs(2), || client
        .latest()
        .is_err()));
    assert!(
        client
            .latest()
            .unwrap_err()
            .to_string()
            .contains("4 payload bytes")
    );
}

#[test]
fn cnde_client_times_out_on_a_silent_controller() {
    let listener = TcpListener::bind(loopback()).unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    // Accepts (the backlog does) but never answers the config.
    let timeout = Duration::from_millis(200);
    let start = Instant::now();
    let err = CndeClient::connect(&addr, &default_state_names(), 8, timeout)
        .err()
        .unwrap();
    assert!(start.elapsed() < timeout * 5, "took {:?}", start.elapsed());
    assert!(matches!(err, DeployError::Network { .. }), "{err}");
    assert!(err.to_string().contains("config"), "{err}");
    drop(listener);
}
