//! `--twin ADDR`: the digital twin's arm during a deployment rehearsal. Its joint angles come
//! over the controller's CNDE stream; a scene of its own is posed at them and rendered.

use super::camera::{Orbit, RgbFrame};
use anyhow::{Context, Result};
use fairgrasp_deploy::fairino::cnde::{CndeClient, DEFAULT_PERIOD_MS, default_state_names};
use fairgrasp_render::{Camera, Renderer};
use fairgrasp_sim::scene::{Scene, SceneConfig};
use std::time::Duration;

pub struct TwinView {
    addr: String,
    client: CndeClient,
    scene: Scene,
    renderer: Option<Renderer>,
    joints_deg: Vec<f64>,
}

impl TwinView {
    /// Subscribes to the CNDE stream at `addr` ("ip:port", the twin's 20005 by default) and
    /// builds a scene like the env's to pose.
    pub fn connect(addr: &str, config: SceneConfig) -> Result<Self> {
        let client = CndeClient::connect(
            addr,
            &default_state_names(),
            DEFAULT_PERIOD_MS,
            Duration::from_secs(5),
        )
        .with_context(|| format!("cannot subscribe to the twin's CNDE stream at {addr}"))?;
        let scene = Scene::new(config).context("cannot build the twin's scene")?;
        let mut twin = Self {
            addr: addr.to_string(),
            client,
            scene,
            renderer: None,
            joints_deg: Vec::new(),
        };
        twin.update()?;
        Ok(twin)
    }

    pub fn addr(&self) -> &str {
        &self.addr
    }

    /// The last joint angles read (degrees, j1…j6).
    pub fn joints_deg(&self) -> &[f64] {
        &self.joints_deg
    }

    /// Poses the scene's arm at the latest streamed joint angles.
    pub fn update(&mut self) -> Result<()> {
        let latest = self
            .client
            .latest()
            .with_context(|| format!("the twin's CNDE stream at {}", self.addr))?;
        self.joints_deg = latest.state.joints_deg.to_vec();
        let dof = self.scene.arm_dof().min(self.joints_deg.len());
        let q: Vec<f32> = self.joints_deg[..dof]
            .iter()
            .map(|d| d.to_radians() as f32)
            .collect();
        self.scene.set_arm_positions(&q)?;
        Ok(())
    }

    /// The twin's arm seen from `orbit`: (width, height, RGB).
    pub fn frame(&mut self, orbit: &Orbit, size: (u32, u32)) -> Result<RgbFrame> {
        self.update()?;
        let config = orbit.camera(size.0, size.1);
        let renderer = match &mut self.renderer {
            Some(r) => {
                r.set_camera(Camera::new(config)?);
                r
            }
            None => self
                .renderer
                .insert(Renderer::with_config(&self.scene, config)?),
        };
        renderer.render(&self.scene)?;
        Ok((renderer.width(), renderer.height(), renderer.rgb().to_vec()))
    }
}
