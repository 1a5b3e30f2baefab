//! The object-pose feed: the twin plays the user's perception, publishing object 0's pose as
//! [`PoseMessage`] JSON lines (robot base frame, metres) at about 30 Hz — to every client
//! connected to a TCP port, and optionally as UDP datagrams (one message each) to an address.

use super::periodic_server::PeriodicServer;
use crate::pose_source::PoseMessage;
use std::io::{self, Write};
use std::net::{SocketAddr, TcpStream, UdpSocket};
use std::sync::Arc;
use std::time::Duration;

/// Where the feed's messages come from: `None` while there is no object.
pub type PoseSourceFn = Arc<dyn Fn() -> Option<PoseMessage> + Send + Sync>;

/// A running feed; stops when dropped.
pub struct PoseFeed {
    server: PeriodicServer,
}

impl PoseFeed {
    /// Listens on `bind` (port 0: any free port) and publishes every `period`.
    pub fn spawn(
        bind: SocketAddr,
        udp_target: Option<SocketAddr>,
        period: Duration,
        source: PoseSourceFn,
    ) -> io::Result<Self> {
        let udp = match udp_target {
            Some(target) => {
                let any: SocketAddr = if target.is_ipv4() {
                    "0.0.0.0:0".parse().expect("literal address")
                } else {
                    "[::]:0".parse().expect("literal address")
                };
                Some((UdpSocket::bind(any)?, target))
            }
            None => None,
        };
        // Non-blocking writes: a client that stops reading is dropped, not waited for.
        let prepare = |stream: &TcpStream| {
            stream.set_nonblocking(true)?;
            stream.set_nodelay(true)
        };
        let tick = move |clients: &mut Vec<TcpStream>| {
            let Some(json) = source().and_then(|m| serde_json::to_string(&m).ok()) else {
                return;
            };
            let line = format!("{json}\n");
            clients.retain_mut(|c| c.write_all(line.as_bytes()).is_ok());
            if let Some((socket, target)) = &udp {
                // A lost datagram is what UDP means; the next one follows in a period.
                let _ = socket.send_to(json.as_bytes(), target);
            }
        };
        let server = PeriodicServer::spawn("twin-pose-feed", bind, period, prepare, tick)?;
        Ok(Self { server })
    }

    /// The TCP address clients connect to.
    pub fn local_addr(&self) -> SocketAddr {
        self.server.local_addr()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{BufRead, BufReader};

    #[test]
    fn every_client_and_the_udp_target_get_lines() {
        let udp = UdpSocket::bind("127.0.0.1:0").unwrap();
        udp.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let source: PoseSourceFn = Arc::new(|| {
            Some(PoseMessage {
                position: [0.4, 0.1, 0.02],
                orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
                stamp: Some(1.5),
            })
        });
        let feed = PoseFeed::spawn(
            "127.0.0.1:0".parse().unwrap(),
            Some(udp.local_addr().unwrap()),
            Duration::from_millis(10),
            source,
        )
        .unwrap();
        let read_line = || {
            let stream = TcpStream::connect(feed.local_addr()).unwrap();
            stream
                .set_read_timeout(Some(Duration::from_secs(5)))
                .unwrap();
            let mut line = String::new();
            BufReader::new(stream).read_line(&mut line).unwrap();
            serde_json::from_str::<PoseMessage>(&line).unwrap()
        };
        let (a, b) = (read_line(), read_line());
        assert_eq!(a.position, [0.4, 0.1, 0.02]);
        assert_eq!(a, b);
        let mut buf = [0u8; 512];
        let n = udp.recv(&mut buf).unwrap();
        let m: PoseMessage = serde_json::from_slice(&buf[..n]).unwrap();
        assert_eq!(m.stamp, Some(1.5));
    }
}
