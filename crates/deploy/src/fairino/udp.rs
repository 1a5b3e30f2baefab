//! The controller's real-time command path: UDP port 20007, the vendor SDK's `cmdType = 1`
//! for `ServoMoveStart`, `ServoJ` and `ServoMoveEnd` (fairino-cnde.md §5). Each command is one
//! ASCII datagram, `/f/bIII{count}III{id}III{len}III{content}III/b/f`, sent without waiting for
//! a reply: a late XML-RPC reply cannot hold the servo loop back.
//!
//! - [`encode`] / [`decode`]: the framing, both sides (the twin serves the port).
//! - [`ServoSender`]: the client's socket, with the SDK's wrapping counter.

use crate::{DeployError, Result};
use std::net::{SocketAddr, ToSocketAddrs, UdpSocket};
use std::time::Duration;

/// The controller's real-time command port.
pub const DEFAULT_PORT: u16 = 20007;
/// Command ids (the SDK's).
pub const SERVO_MOVE_START: u16 = 689;
/// Command id of `ServoMoveEnd()`.
pub const SERVO_MOVE_END: u16 = 690;
/// Command id of `ServoJ(…)` ([`servo_j_content`]).
pub const SERVO_J: u16 = 376;

const HEAD: &str = "/f/b";
const TAIL: &str = "/b/f";
const SEP: &str = "III";
/// Larger than any servo command (a ServoJ with four external axes is ~140 bytes).
pub const MAX_DATAGRAM: usize = 1024;

/// One decoded datagram.
#[derive(Clone, Debug, PartialEq)]
pub struct UdpCommand {
    /// The sender's counter, wrapping after 65535.
    pub count: u16,
    /// The command id ([`SERVO_J`], …).
    pub id: u16,
    /// The call, e.g. `ServoMoveStart()`.
    pub content: String,
}

/// The datagram for command `id` with `content` (e.g. `ServoMoveStart()`).
pub fn encode(count: u16, id: u16, content: &str) -> String {
    format!(
        "{HEAD}{SEP}{count}{SEP}{id}{SEP}{}{SEP}{content}{SEP}{TAIL}",
        content.len()
    )
}

/// Parses a datagram; the error says what is wrong with it.
pub fn decode(bytes: &[u8]) -> std::result::Result<UdpCommand, String> {
    let text = std::str::from_utf8(bytes).map_err(|_| "not ASCII text".to_string())?;
    let body = text
        .strip_prefix(HEAD)
        .and_then(|t| t.strip_suffix(TAIL))
        .ok_or_else(|| format!("not framed by {HEAD} … {TAIL}"))?;
    let body = body
        .strip_prefix(SEP)
        .and_then(|t| t.strip_suffix(SEP))
        .ok_or_else(|| format!("fields not separated by {SEP}"))?;
    let mut fields = body.splitn(4, SEP);
    let mut number = |what: &str| -> std::result::Result<u64, String> {
        let field = fields.next().ok_or_else(|| format!("no {what} field"))?;
        field
            .parse::<u64>()
            .map_err(|_| format!("{what} '{field}' is not a number"))
    };
    let count = number("count")?;
    let id = number("command id")?;
    let len = number("length")?;
    let content = fields.next().ok_or("no content field")?;
    let count = u16::try_from(count).map_err(|_| format!("count {count} exceeds 65535"))?;
    let id = u16::try_from(id).map_err(|_| format!("command id {id} exceeds 65535"))?;
    if len != content.len() as u64 {
        return Err(format!(
            "length field {len} but the content has {} bytes",
            content.len()
        ));
    }
    Ok(UdpCommand {
        count,
        id,
        content: content.to_string(),
    })
}

/// The content of a ServoJ: six joints, four external axes, acc, vel, cmdT, filterT and gain
/// as `{:.4}`, then the id (the SDK's layout).
pub fn servo_j_content(joints_deg: &[f64; 6], cmd_t: f64) -> String {
    let numbers: Vec<String> = joints_deg
        .iter()
        .chain(&[0.0; 4]) // external axes
        .chain(&[0.0, 0.0, cmd_t, 0.0, 0.0]) // acc, vel, cmdT, filterT, gain
        .map(|v| format!("{v:.4}"))
        .collect();
    format!("ServoJ({},0)", numbers.join(","))
}

/// The numbers of a call's content, `Name(a,b,…)`, checked against `name`.
pub fn call_arguments(content: &str, name: &str) -> std::result::Result<Vec<f64>, String> {
    let inner = content
        .strip_prefix(name)
        .and_then(|t| t.strip_prefix('('))
        .and_then(|t| t.strip_suffix(')'))
        .ok_or_else(|| format!("expected {name}(…), got '{content}'"))?;
    if inner.trim().is_empty() {
        return Ok(Vec::new());
    }
    inner
        .split(',')
        .map(|v| {
            v.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("argument '{v}' of {name} is not a finite number"))
        })
        .collect()
}

/// The client side: one socket to the controller's port, the SDK's counter.
pub struct ServoSender {
    socket: UdpSocket,
    target: SocketAddr,
    count: u16,
}

impl ServoSender {
    /// A socket for `addr` (`ip:port`). Sending never blocks longer than `timeout`.
    pub fn connect(addr: &str, timeout: Duration) -> Result<Self> {
        let network = |message: String| DeployError::Network {
            call: "UDP servo".into(),
            addr: addr.to_string(),
            message,
        };
        let target = addr
            .to_socket_addrs()
            .map_err(|e| network(e.to_string()))?
            .next()
            .ok_or_else(|| network("no address".into()))?;
        let any: SocketAddr = if target.is_ipv4() {
            "0.0.0.0:0".parse().expect("literal address")
        } else {
            "[::]:0".parse().expect("literal address")
        };
        let socket = UdpSocket::bind(any).map_err(|e| network(e.to_string()))?;
        socket
            .set_write_timeout(Some(timeout))
            .map_err(|e| network(e.to_string()))?;
        Ok(Self {
            socket,
            target,
            count: 0,
        })
    }

    /// The controller's address.
    pub fn target(&self) -> SocketAddr {
        self.target
    }

    /// Sends one command; returns once the datagram is handed to the network.
    pub fn send(&mut self, id: u16, content: &str) -> Result<()> {
        let datagram = encode(self.count, id, content);
        self.count = self.count.wrapping_add(1);
        self.socket
            .send_to(datagram.as_bytes(), self.target)
            .map(|_| ())
            .map_err(|e| DeployError::Network {
                call: format!("UDP command {id}"),
                addr: self.target.to_string(),
                message: e.to_string(),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_servo_j_round_trips_in_the_sdks_layout() {
        let content = servo_j_content(&[1.0, -2.5, 3.25, 0.0, 90.0, -180.0], 0.008);
        assert_eq!(
            content,
            "ServoJ(1.0000,-2.5000,3.2500,0.0000,90.0000,-180.0000,0.0000,0.0000,0.0000,\
             0.0000,0.0000,0.0000,0.0080,0.0000,0.0000,0)"
        );
        let datagram = encode(65535, SERVO_J, &content);
        assert!(datagram.starts_with("/f/bIII65535III376III"));
        let back = decode(datagram.as_bytes()).unwrap();
        assert_eq!((back.count, back.id), (65535, SERVO_J));
        let args = call_arguments(&back.content, "ServoJ").unwrap();
        assert_eq!(args.len(), 16);
        assert_eq!(args[..6], [1.0, -2.5, 3.25, 0.0, 90.0, -180.0]);
        assert_eq!(args[12], 0.008);
        let start = decode(encode(0, SERVO_MOVE_START, "ServoMoveStart()").as_bytes()).unwrap();
        assert_eq!(call_arguments(&start.content, "ServoMoveStart"), Ok(vec![]));
    }

    #[test]
    fn malformed_datagrams_are_named_not_obeyed() {
        let good = encode(3, SERVO_J, "ServoJ(1,2,3,4,5,6,0,0,0,0,0,0,0.008,0,0,0)");
        for (bad, why) in [
            (&b"\xff\xfe"[..], "ASCII"),
            (b"hello", "framed"),
            (b"/f/b3III376III2IIIabIII/b/f", "separated"),
            (b"/f/bIIIxIII376III2IIIabIII/b/f", "count"),
            (b"/f/bIII1III99999III2IIIabIII/b/f", "exceeds"),
            (b"/f/bIII1III376III5IIIabIII/b/f", "length"),
            (b"/f/bIII1III376III/b/f", "length"),
        ] {
            let err = decode(bad).unwrap_err();
            assert!(err.contains(why), "{bad:?}: {err}");
        }
        assert!(decode(good.as_bytes()).is_ok());
        for (content, why) in [
            ("ServoJ(1,2,nan)", "finite"),
            ("ServoJ(1,2,x)", "finite"),
            ("MoveJ(1,2)", "expected ServoJ"),
            ("ServoJ(1,2", "expected ServoJ"),
        ] {
            let err = call_arguments(content, "ServoJ").unwrap_err();
            assert!(err.contains(why), "{content}: {err}");
        }
    }
}
