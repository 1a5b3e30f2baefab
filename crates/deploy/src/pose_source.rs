//! Where the object's pose comes from on the real arm: a fixed pose, or JSON lines from the
//! user's perception over UDP or TCP.
//!
//! One message per line (UDP: one per datagram), positions in metres and orientation as a
//! unit quaternion, both in the **robot base frame**:
//!
//! ```json
//! {"position": [0.45, 0.02, 0.0225], "orientation_xyzw": [0, 0, 0, 1], "stamp": 12.5}
//! ```
//!
//! `orientation_xyzw` is optional (identity); `stamp` (seconds, the sender's clock) is
//! optional and only logged.

use crate::error::{DeployError, Result, is_timeout};
use fairgrasp_sim::rapier3d::na::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};
use std::io::{BufRead, BufReader};
use std::net::{TcpStream, ToSocketAddrs, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// One object pose message.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseMessage {
    /// Object centre in the robot base frame (m).
    pub position: [f64; 3],
    /// Unit quaternion x, y, z, w (identity when absent).
    #[serde(default = "identity")]
    pub orientation_xyzw: [f64; 4],
    /// The sender's time stamp (s, its own clock); only logged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stamp: Option<f64>,
}

fn identity() -> [f64; 4] {
    [0.0, 0.0, 0.0, 1.0]
}

impl PoseMessage {
    /// Parses one line; errors say what is wrong with it.
    pub fn parse(line: &str) -> Result<Self> {
        let msg: Self = serde_json::from_str(line.trim()).map_err(|e| {
            DeployError::Protocol(format!("object pose message `{}`: {e}", line.trim()))
        })?;
        msg.check()?;
        Ok(msg)
    }

    fn check(&self) -> Result<()> {
        if !self
            .position
            .iter()
            .all(|v| v.is_finite() && v.abs() < 10.0)
        {
            return Err(DeployError::Protocol(format!(
                "object pose: position {:?} m must be finite and within 10 m of the base",
                self.position
            )));
        }
        let q = self.orientation_xyzw;
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !(norm.is_finite() && (norm - 1.0).abs() < 1e-2) {
            return Err(DeployError::Protocol(format!(
                "object pose: orientation_xyzw {q:?} is not a unit quaternion (norm {norm})"
            )));
        }
        Ok(())
    }

    /// The pose as an isometry (base frame, m).
    pub fn isometry(&self) -> Isometry3<f64> {
        let [x, y, z, w] = self.orientation_xyzw;
        Isometry3::from_parts(
            Translation3::new(self.position[0], self.position[1], self.position[2]),
            UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
        )
    }
}

/// A pose with the moment it arrived.
#[derive(Clone, Debug)]
pub struct ReceivedPose {
    /// The message as received.
    pub message: PoseMessage,
    /// When it was received (this machine's clock).
    pub received_at: Instant,
}

/// Where the deployment loop reads the object's pose.
pub trait PoseSource: Send {
    /// The newest pose received so far (does not block), or an error when the source failed.
    fn latest(&mut self) -> Result<Option<ReceivedPose>>;

    /// Waits up to `timeout` for a first pose.
    fn wait_first(&mut self, timeout: Duration) -> Result<ReceivedPose> {
        let until = Instant::now() + timeout;
        loop {
            if let Some(p) = self.latest()? {
                return Ok(p);
            }
            if Instant::now() >= until {
                return Err(DeployError::Other(format!(
                    "no object pose within {:.1} s; is the perception (or the twin's pose \
                     feed) sending?",
                    timeout.as_secs_f64()
                )));
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

/// A pose given on the command line, for an object that does not move until grasped.
pub struct FixedPose(pub PoseMessage);

impl PoseSource for FixedPose {
    fn latest(&mut self) -> Result<Option<ReceivedPose>> {
        Ok(Some(ReceivedPose {
            message: self.0.clone(),
            received_at: Instant::now(),
        }))
    }
}

/// Newest message and the failure of a receiving thread, shared with it.
#[derive(Default)]
struct Shared {
    latest: Option<ReceivedPose>,
    error: Option<String>,
}

/// JSON lines from a receiving thread (UDP datagrams or a TCP connection).
pub struct StreamedPose {
    shared: Arc<Mutex<Shared>>,
    stop: Arc<AtomicBool>,
}

impl StreamedPose {
    /// Listens for datagrams on `bind` (e.g. `127.0.0.1:20102`), one message each.
    pub fn udp(bind: &str) -> Result<Self> {
        let socket = UdpSocket::bind(bind).map_err(|e| net_error("bind UDP", bind, e))?;
        socket.set_read_timeout(Some(Duration::from_millis(50)))?;
        let (shared, stop) = (
            Arc::new(Mutex::new(Shared::default())),
            Arc::new(AtomicBool::new(false)),
        );
        let (s, st) = (shared.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while !st.load(Ordering::Relaxed) {
                match socket.recv(&mut buf) {
                    Ok(n) => store(&s, std::str::from_utf8(&buf[..n]).unwrap_or("")),
                    Err(e) if is_timeout(&e) => {}
                    Err(e) => {
                        lock(&s).error = Some(format!("UDP receive: {e}"));
                        return;
                    }
                }
            }
        });
        Ok(Self { shared, stop })
    }

    /// Connects to `addr` (e.g. the twin's feed at `127.0.0.1:20100`) and reads lines.
    pub fn tcp(addr: &str, connect_timeout: Duration) -> Result<Self> {
        let sock_addr = addr
            .to_socket_addrs()
            .map_err(|e| net_error("resolve", addr, e))?
            .next()
            .ok_or_else(|| DeployError::config("pose source", format!("{addr}: no address")))?;
        let stream = TcpStream::connect_timeout(&sock_addr, connect_timeout)
            .map_err(|e| net_error("connect", addr, e))?;
        stream.set_read_timeout(Some(Duration::from_millis(50)))?;
        let (shared, stop) = (
            Arc::new(Mutex::new(Shared::default())),
            Arc::new(AtomicBool::new(false)),
        );
        let (s, st) = (shared.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut reader = BufReader::new(stream);
            let mut line = String::new();
            while !st.load(Ordering::Relaxed) {
                match reader.read_line(&mut line) {
                    Ok(0) => {
                        lock(&s).error = Some("the pose feed closed the connection".into());
                        return;
                    }
                    Ok(_) => {
                        store(&s, &line);
                        line.clear();
                    }
                    // A timeout keeps the partial line in `line` for the next read.
                    Err(e) if is_timeout(&e) => {}
                    Err(e) => {
                        lock(&s).error = Some(format!("pose feed: {e}"));
                        return;
                    }
                }
            }
        });
        Ok(Self { shared, stop })
    }
}

impl PoseSource for StreamedPose {
    fn latest(&mut self) -> Result<Option<ReceivedPose>> {
        let s = lock(&self.shared);
        match &s.error {
            Some(e) => Err(DeployError::Other(e.clone())),
            None => Ok(s.latest.clone()),
        }
    }
}

impl Drop for StreamedPose {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn lock(s: &Mutex<Shared>) -> std::sync::MutexGuard<'_, Shared> {
    s.lock().unwrap_or_else(|p| p.into_inner())
}

/// Keeps a good message; a bad one is the source's failure (perception sending garbage
/// must not be acted on).
fn store(s: &Mutex<Shared>, text: &str) {
    if text.trim().is_empty() {
        return;
    }
    let mut s = lock(s);
    match PoseMessage::parse(text) {
        Ok(message) => {
            s.latest = Some(ReceivedPose {
                message,
                received_at: Instant::now(),
            })
        }
        Err(e) => s.error = Some(e.to_string()),
    }
}

fn net_error(call: &str, addr: &str, e: std::io::Error) -> DeployError {
    DeployError::Network {
        call: format!("pose source: {call}"),
        addr: addr.into(),
        message: e.to_string(),
    }
}

/// Parses a `--object-pose` value: `x,y,z` in metres (base frame), optionally `,yaw_deg`.
pub fn parse_fixed_pose(text: &str) -> Result<PoseMessage> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| DeployError::config("--object-pose", format!("`{text}`: {e}")))?;
    if !(values.len() == 3 || values.len() == 4) {
        return Err(DeployError::config(
            "--object-pose",
            format!("`{text}`: expected x,y,z (m) or x,y,z,yaw_deg"),
        ));
    }
    let yaw = values.get(3).copied().unwrap_or(0.0).to_radians();
    let msg = PoseMessage {
        position: [values[0], values[1], values[2]],
        orientation_xyzw: [0.0, 0.0, (yaw / 2.0).sin(), (yaw / 2.0).cos()],
        stamp: None,
    };
    msg.check()?;
    Ok(msg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_parse_and_bad_ones_are_named() {
        let m = PoseMessage::parse(r#"{"position": [0.45, 0.02, 0.0225]}"#).unwrap();
        assert_eq!(m.orientation_xyzw, [0.0, 0.0, 0.0, 1.0]);
        assert!((m.isometry().translation.x - 0.45).abs() < 1e-12);
        let e = PoseMessage::parse(r#"{"position": [0.45, 0.02]}"#).unwrap_err();
        assert!(e.to_string().contains("object pose message"), "{e}");
        let e =
            PoseMessage::parse(r#"{"position": [0.4, 0, 0], "orientation_xyzw": [0, 0, 0, 2]}"#)
                .unwrap_err();
        assert!(e.to_string().contains("unit quaternion"), "{e}");
        let e = PoseMessage::parse(r#"{"position": [0.4, 0, 0], "extra": 1}"#).unwrap_err();
        assert!(e.to_string().contains("extra"), "{e}");
    }

    #[test]
    fn fixed_poses_parse_with_yaw() {
        let m = parse_fixed_pose("0.5, 0.1, 0.02, 90").unwrap();
        let yaw = m.isometry().rotation.euler_angles().2;
        assert!((yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        assert!(parse_fixed_pose("0.5,0.1").is_err());
        assert!(parse_fixed_pose("0.5,a,0").is_err());
        assert!(parse_fixed_pose("nan,0,0").is_err());
    }

    #[test]
    fn udp_and_tcp_sources_deliver_the_newest_pose_and_reject_garbage() {
        // UDP.
        let mut udp = StreamedPose::udp("127.0.0.1:0").unwrap_or_else(|e| panic!("{e}"));
        drop(udp);
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        let port = socket.local_addr().unwrap().port();
        drop(socket);
        udp = StreamedPose::udp(&format!("127.0.0.1:{port}")).unwrap();
        let sender = UdpSocket::bind("127.0.0.1:0").unwrap();
        sender
            .send_to(br#"{"position": [0.4, 0.0, 0.02]}"#, ("127.0.0.1", port))
            .unwrap();
        let p = udp.wait_first(Duration::from_secs(2)).unwrap();
        assert_eq!(p.message.position, [0.4, 0.0, 0.02]);
        // TCP: a line split across writes arrives whole; garbage fails the source.
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap().to_string();
        let server = std::thread::spawn(move || {
            use std::io::Write;
            let (mut c, _) = listener.accept().unwrap();
            c.write_all(br#"{"position": [0.5, "#).unwrap();
            c.flush().unwrap();
            std::thread::sleep(Duration::from_millis(80));
            c.write_all(b"0.1, 0.02]}\n").unwrap();
            std::thread::sleep(Duration::from_millis(200));
            c.write_all(b"not json\n").unwrap();
            std::thread::sleep(Duration::from_millis(300));
        });
        let mut tcp = StreamedPose::tcp(&addr, Duration::from_secs(1)).unwrap();
        let p = tcp.wait_first(Duration::from_secs(2)).unwrap();
        assert_eq!(p.message.position, [0.5, 0.1, 0.02]);
        std::thread::sleep(Duration::from_millis(300));
        let e = tcp.latest().unwrap_err();
        assert!(e.to_string().contains("not json"), "{e}");
        server.join().unwrap();
    }
}
