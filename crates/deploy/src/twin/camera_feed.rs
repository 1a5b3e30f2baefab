//! The camera feed: the twin plays the cell's camera, drawing the staged scene from the camera
//! the staged environment observes with (`[camera]`: scene and wrist cameras, RGB or depth) and
//! serving each view as a frame of [`crate::frame_source`]'s protocol, at about 30 Hz, to
//! every client connected to a TCP port. The look is the nominal one: a real cell's camera has
//! one light and one set of colours, not the training's randomised draws.

use super::periodic_server::PeriodicServer;
use crate::error::{DeployError, Result};
use crate::frame_source::{FrameHeader, write_frame};
use fairgrasp_env::arm::camera::{CameraObsConfig, Cameras};
use fairgrasp_env::spaces::ImageSpace;
use fairgrasp_sim::scene::Scene;
use std::io;
use std::net::{SocketAddr, TcpStream};
use std::sync::Arc;
use std::time::Duration;

/// The cameras of a staged environment, drawing frames of its scene.
pub struct TwinCamera {
    cameras: Cameras,
}

impl TwinCamera {
    /// The cameras the environment settings `table` observe with (its `[camera]`), or `None`
    /// when it observes no images. Visual randomisation and the training's image delay are left
    /// off.
    pub fn for_env(table: &toml::Table, scene: &Scene) -> Result<Option<Self>> {
        let mut config: CameraObsConfig = match table.get("camera") {
            Some(value) => value.clone().try_into().map_err(|e| {
                DeployError::config("camera", format!("the staged camera settings: {e}"))
            })?,
            None => return Ok(None),
        };
        config.randomize.enabled = false;
        // Frames are as fresh as drawn: the feed's delay is its own, in time.
        config.delay_steps = [0, 0];
        Ok(Cameras::new(&config, scene)?.map(|cameras| Self { cameras }))
    }

    /// The images' layout.
    pub fn space(&self) -> &ImageSpace {
        self.cameras.space()
    }

    /// Every view of `scene` as it is now, stamped `stamp` (s): a header and the pixels each.
    pub fn frames(&mut self, scene: &Scene, stamp: f64) -> Result<Vec<(FrameHeader, Vec<u8>)>> {
        self.cameras.capture(scene)?;
        let image = self.cameras.image();
        let space = self.cameras.space();
        Ok((space.views.iter().enumerate())
            .map(|(i, v)| {
                let header = FrameHeader {
                    camera: v.name.clone(),
                    height: v.height,
                    width: v.width,
                    channels: v.channels,
                    stamp,
                };
                (header, image[space.range(i)].to_vec())
            })
            .collect())
    }
}

/// Where the feed's frames come from: `None` while there are none to send.
pub type FramesFn = Arc<dyn Fn() -> Option<Vec<(FrameHeader, Vec<u8>)>> + Send + Sync>;

/// A client that takes longer than this to accept a frame is dropped.
const WRITE_TIMEOUT: Duration = Duration::from_millis(200);

/// A running feed; stops when dropped.
pub struct CameraFeed {
    server: PeriodicServer,
}

impl CameraFeed {
    /// Listens on `bind` (port 0: any free port) and sends every `period`.
    pub fn spawn(bind: SocketAddr, period: Duration, source: FramesFn) -> io::Result<Self> {
        // Blocking writes with a deadline: a frame is sent whole or the client is dropped.
        let prepare = |stream: &TcpStream| {
            stream.set_nonblocking(false)?;
            stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
            stream.set_nodelay(true)
        };
        let tick = move |clients: &mut Vec<TcpStream>| {
            if clients.is_empty() {
                return;
            }
            let Some(frames) = source() else {
                return;
            };
            let mut bytes = Vec::new();
            for (header, pixels) in &frames {
                // Sizes come from the camera that drew the pixels.
                let _ = write_frame(&mut bytes, header, pixels);
            }
            clients.retain_mut(|c| io::Write::write_all(c, &bytes).is_ok());
        };
        let server = PeriodicServer::spawn("twin-camera-feed", bind, period, prepare, tick)?;
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
    use crate::frame_source::{FrameSource, TcpFrames};
    use crate::twin::world::World;

    #[test]
    fn the_feed_serves_the_staged_cameras_frames_to_the_deployments_reader() {
        let mut table = toml::Table::new();
        for item in [
            "camera.mode=\"rgb+state\"",
            "camera.width=32",
            "camera.height=24",
        ] {
            fairgrasp_env::config::apply_override(&mut table, item).unwrap();
        }
        let world = World::new("FaArmGrasp-v0", &table, 0).unwrap();
        let mut camera = TwinCamera::for_env(&table, world.scene()).unwrap().unwrap();
        let space = camera.space().clone();
        assert_eq!(space.describe(), "scene_rgb 24×32×3");
        let frames = camera.frames(world.scene(), 1.25).unwrap();
        assert_eq!(frames.len(), 1);
        let pixels = frames[0].1.clone();
        assert!(
            pixels.iter().any(|&p| p != pixels[0]),
            "a picture, not a blank"
        );

        let source: FramesFn = Arc::new(move || Some(frames.clone()));
        let feed = CameraFeed::spawn(
            "127.0.0.1:0".parse().unwrap(),
            Duration::from_millis(10),
            source,
        )
        .unwrap();
        let mut reader = TcpFrames::connect(
            &feed.local_addr().to_string(),
            &space,
            Duration::from_secs(2),
            Duration::from_secs(2),
        )
        .unwrap();
        let images = reader.wait_first(Duration::from_secs(5)).unwrap();
        assert_eq!(images.bytes, pixels);
        assert_eq!(images.stamps, [1.25]);

        let none = TwinCamera::for_env(&toml::Table::new(), world.scene()).unwrap();
        assert!(none.is_none(), "a state policy's environment has no camera");
    }
}
