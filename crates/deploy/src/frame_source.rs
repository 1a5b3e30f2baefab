//! Where a camera policy's images come from on the real arm: frames over TCP from the user's
//! camera (or the twin's rendered one).
//!
//! The image source serves, the deployment connects. Each frame is one JSON header line, then
//! its pixels:
//!
//! ```text
//! {"camera": "scene_rgb", "height": 64, "width": 64, "channels": 3, "stamp": 12.503}\n
//! <height · width · channels bytes>
//! ```
//!
//! `camera` names the image as the policy's observation does (`scene_rgb`, `wrist_depth`, …);
//! the pixels are `u8`, row by row from the top, each pixel's channels together (R, G, B, then
//! depth for `rgbd`, depth as `camera.near`…`camera.far` mapped onto 0…255). `stamp` is the
//! sender's clock (s) at capture, logged beside each step. A frame of another size than the
//! policy reads, a header that is not JSON, or a feed that goes quiet is the source's failure;
//! frames of cameras the policy does not read are skipped. The deployment refuses images older
//! than `safety.frame_deadline_ms` (by this machine's clock at arrival).

use crate::error::{DeployError, Result, is_timeout};
use fairgrasp_env::spaces::ImageSpace;
use serde::{Deserialize, Serialize};
use std::io::{Read, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The largest header line accepted (bytes): a header is about 90.
const MAX_HEADER: usize = 1024;
/// The largest image side accepted (pixels).
const MAX_SIDE: u32 = 4096;
/// The most channels accepted (RGB-D has 4).
const MAX_CHANNELS: u32 = 4;

/// One frame's header line.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameHeader {
    /// The image's name in the policy's observation (`scene_rgb`).
    pub camera: String,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Values per pixel (3 for RGB, 1 for depth, 4 for RGB-D).
    pub channels: u32,
    /// The sender's clock at capture (s).
    pub stamp: f64,
}

impl FrameHeader {
    /// Bytes of the pixels that follow.
    pub fn len(&self) -> usize {
        self.height as usize * self.width as usize * self.channels as usize
    }

    /// Whether the frame has no pixels (never valid).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn parse(line: &[u8]) -> Result<Self> {
        let text = String::from_utf8_lossy(line);
        let header: Self = serde_json::from_str(text.trim()).map_err(|e| {
            DeployError::Protocol(format!("camera frame header `{}`: {e}", text.trim()))
        })?;
        let sides_ok = (1..=MAX_SIDE).contains(&header.height)
            && (1..=MAX_SIDE).contains(&header.width)
            && (1..=MAX_CHANNELS).contains(&header.channels);
        if !sides_ok || !header.stamp.is_finite() {
            return Err(DeployError::Protocol(format!(
                "camera frame header `{}`: sizes must be 1-{MAX_SIDE} pixels and 1-{MAX_CHANNELS} \
                 channels, the stamp finite",
                text.trim()
            )));
        }
        Ok(header)
    }
}

/// Writes one frame: its header line, then `pixels` (what an image source sends).
pub fn write_frame(
    out: &mut impl Write,
    header: &FrameHeader,
    pixels: &[u8],
) -> std::io::Result<()> {
    if pixels.len() != header.len() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!(
                "{} bytes for a {}×{}×{} frame",
                pixels.len(),
                header.height,
                header.width,
                header.channels
            ),
        ));
    }
    let mut line = serde_json::to_vec(header).map_err(std::io::Error::other)?;
    line.push(b'\n');
    out.write_all(&line)?;
    out.write_all(pixels)
}

/// The images a camera policy reads, every camera's newest frame joined in the policy's order.
#[derive(Clone, Debug)]
pub struct ReceivedImages {
    /// Every camera's pixels, one after another ([`ImageSpace`] order).
    pub bytes: Vec<u8>,
    /// When the oldest of them arrived (this machine's clock).
    pub received_at: Instant,
    /// The senders' stamps, per camera.
    pub stamps: Vec<f64>,
}

/// Where the deployment loop reads a camera policy's images.
pub trait FrameSource: Send {
    /// The newest frame of every camera (does not block): `None` until each camera has sent
    /// one, an error when the source failed.
    fn latest(&mut self) -> Result<Option<ReceivedImages>>;

    /// Waits up to `timeout` for a first frame of every camera.
    fn wait_first(&mut self, timeout: Duration) -> Result<ReceivedImages> {
        let until = Instant::now() + timeout;
        loop {
            if let Some(images) = self.latest()? {
                return Ok(images);
            }
            if Instant::now() >= until {
                return Err(DeployError::Other(format!(
                    "no camera frames within {:.1} s; is the camera feed (or the twin's) sending?",
                    timeout.as_secs_f64()
                )));
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

/// Collects frames into the newest of each camera; a bad frame is the source's failure.
pub struct FrameCollector {
    space: ImageSpace,
    newest: Vec<Option<(Vec<u8>, Instant, f64)>>,
}

impl FrameCollector {
    /// Keeps the cameras of `space`.
    pub fn new(space: &ImageSpace) -> Self {
        Self {
            space: space.clone(),
            newest: vec![None; space.views.len()],
        }
    }

    /// Takes one frame received at `at`; frames of cameras not in the space are skipped.
    pub fn take(&mut self, header: &FrameHeader, pixels: Vec<u8>, at: Instant) -> Result<()> {
        let Some(i) = (self.space.views.iter()).position(|v| v.name == header.camera) else {
            return Ok(());
        };
        let v = &self.space.views[i];
        if (header.height, header.width, header.channels) != (v.height, v.width, v.channels) {
            return Err(DeployError::Protocol(format!(
                "camera frame `{}` is {}×{}×{}; the policy reads {}×{}×{} (height × width × \
                 channels): resize it before sending",
                header.camera,
                header.height,
                header.width,
                header.channels,
                v.height,
                v.width,
                v.channels
            )));
        }
        self.newest[i] = Some((pixels, at, header.stamp));
        Ok(())
    }

    /// Every camera's newest frame, once each has one.
    pub fn images(&self) -> Option<ReceivedImages> {
        let mut out = ReceivedImages {
            bytes: Vec::with_capacity(self.space.len()),
            received_at: Instant::now(),
            stamps: Vec::new(),
        };
        for view in &self.newest {
            let (pixels, at, stamp) = view.as_ref()?;
            out.bytes.extend_from_slice(pixels);
            out.received_at = out.received_at.min(*at);
            out.stamps.push(*stamp);
        }
        Some(out)
    }
}

#[derive(Default)]
struct Shared {
    images: Option<ReceivedImages>,
    error: Option<String>,
}

/// Frames from a TCP connection to an image source, read on a thread of its own.
pub struct TcpFrames {
    shared: Arc<Mutex<Shared>>,
    stop: Arc<AtomicBool>,
}

impl TcpFrames {
    /// Connects to `addr` (e.g. the twin's feed at `127.0.0.1:20101`) for the cameras of
    /// `space`. A feed silent for `quiet` fails the source.
    pub fn connect(
        addr: &str,
        space: &ImageSpace,
        connect_timeout: Duration,
        quiet: Duration,
    ) -> Result<Self> {
        let net = |call: &str, e: std::io::Error| DeployError::Network {
            call: format!("camera feed: {call}"),
            addr: addr.into(),
            message: e.to_string(),
        };
        let sock_addr = (addr.to_socket_addrs().map_err(|e| net("resolve", e))?)
            .next()
            .ok_or_else(|| DeployError::config("camera feed", format!("{addr}: no address")))?;
        let stream = TcpStream::connect_timeout(&sock_addr, connect_timeout)
            .map_err(|e| net("connect", e))?;
        stream.set_read_timeout(Some(Duration::from_millis(50)))?;
        let shared = Arc::new(Mutex::new(Shared::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let (s, st) = (shared.clone(), stop.clone());
        let mut collector = FrameCollector::new(space);
        std::thread::Builder::new()
            .name("camera-feed".into())
            .spawn(move || {
                let failure = read_frames(stream, &mut collector, &s, &st, quiet);
                if let Err(e) = failure {
                    lock(&s).error = Some(e.to_string());
                }
            })?;
        Ok(Self { shared, stop })
    }
}

/// Reads frames until `stop`, a bad frame, a closed connection or `quiet` without a byte.
fn read_frames(
    mut stream: TcpStream,
    collector: &mut FrameCollector,
    shared: &Mutex<Shared>,
    stop: &AtomicBool,
    quiet: Duration,
) -> Result<()> {
    // Bytes received and not yet parsed: partial reads leave a frame's rest for the next.
    let mut pending: Vec<u8> = Vec::new();
    let mut chunk = vec![0u8; 64 * 1024];
    let mut heard = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        match stream.read(&mut chunk) {
            Ok(0) => {
                return Err(DeployError::Other(
                    "the camera feed closed the connection".into(),
                ));
            }
            Ok(n) => {
                pending.extend_from_slice(&chunk[..n]);
                heard = Instant::now();
            }
            Err(e) if is_timeout(&e) => {
                if heard.elapsed() > quiet {
                    return Err(DeployError::Other(format!(
                        "the camera feed sent nothing for {:.1} s",
                        quiet.as_secs_f64()
                    )));
                }
                continue;
            }
            Err(e) => return Err(DeployError::Other(format!("camera feed: {e}"))),
        }
        let mut used = 0;
        while let Some(end) = pending[used..].iter().position(|&b| b == b'\n') {
            let header = FrameHeader::parse(&pending[used..used + end])?;
            let start = used + end + 1;
            if pending.len() < start + header.len() {
                break;
            }
            let pixels = pending[start..start + header.len()].to_vec();
            collector.take(&header, pixels, Instant::now())?;
            used = start + header.len();
        }
        pending.drain(..used);
        if pending.len() > MAX_HEADER && !pending[..MAX_HEADER].contains(&b'\n') {
            return Err(DeployError::Protocol(format!(
                "camera feed: no header line in the first {MAX_HEADER} bytes of a frame"
            )));
        }
        if let Some(images) = collector.images() {
            lock(shared).images = Some(images);
        }
    }
    Ok(())
}

impl FrameSource for TcpFrames {
    fn latest(&mut self) -> Result<Option<ReceivedImages>> {
        let s = lock(&self.shared);
        match &s.error {
            Some(e) => Err(DeployError::Other(e.clone())),
            None => Ok(s.images.clone()),
        }
    }
}

impl Drop for TcpFrames {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn lock(s: &Mutex<Shared>) -> std::sync::MutexGuard<'_, Shared> {
    s.lock().unwrap_or_else(|p| p.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use fairgrasp_env::spaces::ImageView;
    use std::net::TcpListener;

    fn space() -> ImageSpace {
        ImageSpace {
            views: vec![
                ImageView {
                    name: "scene_rgb".into(),
                    height: 2,
                    width: 3,
                    channels: 3,
                },
                ImageView {
                    name: "wrist_rgb".into(),
                    height: 2,
                    width: 2,
                    channels: 3,
                },
            ],
        }
    }

    fn header(camera: &str, height: u32, width: u32, stamp: f64) -> FrameHeader {
        FrameHeader {
            camera: camera.into(),
            height,
            width,
            channels: 3,
            stamp,
        }
    }

    /// A feed on a free port that runs `send` on its first connection.
    fn feed(send: impl FnOnce(TcpStream) + Send + 'static) -> String {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap().to_string();
        std::thread::spawn(move || send(listener.accept().unwrap().0));
        addr
    }

    fn wait(frames: &mut TcpFrames) -> Result<ReceivedImages> {
        frames.wait_first(Duration::from_secs(5))
    }

    #[test]
    fn frames_split_anywhere_join_into_the_policys_order() {
        let addr = feed(|mut s| {
            let mut bytes = Vec::new();
            write_frame(&mut bytes, &header("wrist_rgb", 2, 2, 1.0), &[7; 12]).unwrap();
            write_frame(&mut bytes, &header("other_rgb", 1, 1, 1.0), &[9; 3]).unwrap();
            write_frame(&mut bytes, &header("scene_rgb", 2, 3, 2.0), &[5; 18]).unwrap();
            // A byte at a time: frames cut anywhere, the header included.
            for b in bytes {
                s.write_all(&[b]).unwrap();
                s.flush().unwrap();
            }
            std::thread::sleep(Duration::from_secs(2));
        });
        let mut frames = TcpFrames::connect(
            &addr,
            &space(),
            Duration::from_secs(2),
            Duration::from_secs(5),
        )
        .unwrap();
        let images = wait(&mut frames).unwrap();
        let mut want = vec![5u8; 18];
        want.extend([7u8; 12]);
        assert_eq!(
            images.bytes, want,
            "scene first, then wrist; the other camera skipped"
        );
        assert_eq!(images.stamps, [2.0, 1.0]);
    }

    #[test]
    fn a_wrong_size_garbage_or_a_silent_feed_fails_the_source_by_name() {
        let wrong = feed(|mut s| {
            write_frame(&mut s, &header("scene_rgb", 4, 4, 0.0), &[0; 48]).unwrap();
            std::thread::sleep(Duration::from_secs(2));
        });
        let garbage = feed(|mut s| {
            s.write_all(b"GET / HTTP/1.1\n").unwrap();
            std::thread::sleep(Duration::from_secs(2));
        });
        let silent = feed(|_s| std::thread::sleep(Duration::from_secs(3)));
        let closed = feed(drop);
        let cases = [
            (wrong, "the policy reads 2×3×3"),
            (garbage, "camera frame header `GET / HTTP/1.1`"),
            (silent, "sent nothing for 0.3 s"),
            (closed, "closed the connection"),
        ];
        for (addr, want) in cases {
            let quiet = Duration::from_millis(300);
            let mut frames =
                TcpFrames::connect(&addr, &space(), Duration::from_secs(2), quiet).unwrap();
            let err = wait(&mut frames).unwrap_err().to_string();
            assert!(err.contains(want), "{err}");
        }
        let refused = TcpFrames::connect(
            "127.0.0.1:1",
            &space(),
            Duration::from_secs(1),
            Duration::from_secs(1),
        );
        assert!(refused.err().unwrap().to_string().contains("127.0.0.1:1"));
    }

    #[test]
    fn a_header_with_absurd_sizes_is_refused_before_any_allocation() {
        let line = br#"{"camera":"scene_rgb","height":100000,"width":3,"channels":3,"stamp":0}"#;
        let err = FrameHeader::parse(line).unwrap_err().to_string();
        assert!(err.contains("1-4096 pixels"), "{err}");
        let err = FrameHeader::parse(br#"{"camera":"x","height":1}"#)
            .unwrap_err()
            .to_string();
        assert!(err.contains("missing field"), "{err}");
        let mut out = Vec::new();
        let short = write_frame(&mut out, &header("scene_rgb", 2, 3, 0.0), &[0; 5]);
        assert!(
            short
                .unwrap_err()
                .to_string()
                .contains("5 bytes for a 2×3×3 frame")
        );
    }
}
