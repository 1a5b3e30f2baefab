//! The twin's real-time command port (UDP 20007 on a controller): `ServoMoveStart`, `ServoJ`
//! and `ServoMoveEnd` sent with the SDK's `cmdType = 1` ([`crate::fairino::udp`]). Each datagram
//! becomes the same call the XML-RPC method makes, with the same checks, and goes into the call
//! log (method `udp:ServoJ` …); nothing is answered, as on the controller. A datagram the twin
//! cannot read is logged with the reason and counted ([`super::TwinHandle::udp_rejected`]).

use super::Shared;
use super::call_log::CallRecord;
use super::service::TwinService;
use crate::fairino::udp::{self, MAX_DATAGRAM};
use crate::fairino::xmlrpc::Value;
use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::thread::JoinHandle;
use std::time::Duration;

/// How often the receiving thread looks at the shutdown flag.
const POLL: Duration = Duration::from_millis(50);

/// A running port; the thread ends with the twin's shutdown flag.
pub struct ServoPort {
    addr: SocketAddr,
    thread: Option<JoinHandle<()>>,
}

impl ServoPort {
    pub(crate) fn spawn(bind: SocketAddr, shared: Arc<Shared>) -> io::Result<Self> {
        let socket = UdpSocket::bind(bind)?;
        socket.set_read_timeout(Some(POLL))?;
        let addr = socket.local_addr()?;
        let thread = std::thread::Builder::new()
            .name("twin-servo-udp".into())
            .spawn(move || run(socket, shared))?;
        Ok(Self {
            addr,
            thread: Some(thread),
        })
    }

    /// Where it listens.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    pub(crate) fn join(&mut self) {
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The XML-RPC method and parameters a datagram stands for.
fn as_call(bytes: &[u8]) -> Result<(&'static str, Vec<Value>), String> {
    let command = udp::decode(bytes)?;
    match command.id {
        udp::SERVO_MOVE_START | udp::SERVO_MOVE_END => {
            let name = if command.id == udp::SERVO_MOVE_START {
                "ServoMoveStart"
            } else {
                "ServoMoveEnd"
            };
            let args = udp::call_arguments(&command.content, name)?;
            if !args.is_empty() {
                return Err(format!("{name} takes no arguments, got {}", args.len()));
            }
            Ok((name, Vec::new()))
        }
        udp::SERVO_J => {
            let args = udp::call_arguments(&command.content, "ServoJ")?;
            // Six joints, four external axes, acc, vel, cmdT, filterT, gain, id.
            if args.len() != 16 {
                return Err(format!("ServoJ needs 16 numbers, got {}", args.len()));
            }
            Ok((
                "ServoJ",
                vec![
                    Value::doubles(&args[..6]),
                    Value::doubles(&args[6..10]),
                    Value::Double(args[10]),
                    Value::Double(args[11]),
                    Value::Double(args[12]),
                    Value::Double(args[13]),
                    Value::Double(args[14]),
                    Value::Int(args[15] as i32),
                ],
            ))
        }
        other => Err(format!("command id {other} is not served on this port")),
    }
}

fn run(socket: UdpSocket, shared: Arc<Shared>) {
    let service = TwinService::new(shared.clone());
    let mut buf = [0u8; MAX_DATAGRAM];
    while !shared.shutdown.load(Ordering::SeqCst) {
        let n = match socket.recv_from(&mut buf) {
            Ok((n, _)) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                continue;
            }
            // Anything else (an ICMP error surfacing): wait a poll period rather than spin.
            Err(_) => {
                std::thread::sleep(POLL);
                continue;
            }
        };
        match as_call(&buf[..n]) {
            Ok((method, params)) => service.call_one_way(method, params),
            Err(reason) => {
                shared.udp_rejected.fetch_add(1, Ordering::Relaxed);
                shared.calls.record(CallRecord {
                    t: shared.now(),
                    method: "udp".into(),
                    params: vec![String::from_utf8_lossy(&buf[..n]).into_owned().into()],
                    reply: serde_json::json!({"rejected": reason}),
                    seconds: 0.0,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn datagrams_become_the_xml_rpc_calls() {
        let j = udp::encode(
            7,
            udp::SERVO_J,
            &udp::servo_j_content(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], 0.008),
        );
        let (method, params) = as_call(j.as_bytes()).unwrap();
        assert_eq!(method, "ServoJ");
        assert_eq!(params.len(), 8);
        assert_eq!(params[4], Value::Double(0.008));
        let start = udp::encode(0, udp::SERVO_MOVE_START, "ServoMoveStart()");
        assert_eq!(
            as_call(start.as_bytes()).unwrap(),
            ("ServoMoveStart", vec![])
        );
        for (bad, why) in [
            (udp::encode(0, 201, "MoveJ()"), "not served"),
            (udp::encode(0, udp::SERVO_J, "ServoJ(1,2,3)"), "16 numbers"),
            (
                udp::encode(0, udp::SERVO_MOVE_END, "ServoMoveEnd(1)"),
                "no arguments",
            ),
            (
                udp::encode(0, udp::SERVO_J, "ServoMoveEnd()"),
                "expected ServoJ",
            ),
        ] {
            let err = as_call(bad.as_bytes()).unwrap_err();
            assert!(err.contains(why), "{bad}: {err}");
        }
    }
}
