//! Camera observations (`[camera]`): the images a pixel policy sees beside the arm's own
//! readings, drawn after every reset and step by the CPU renderer.
//!
//! In a pixel mode the state vector is what the real arm reports (joints, speeds, TCP, gripper,
//! the previous action), never the object's pose; the task's full observation of the true state
//! goes to [`crate::core::Info::privileged`] for a critic that sees it (asymmetric actor-critic).

use crate::error::{EnvError, Result};
use crate::spaces::{ImageSpace, ImageView};
use fairgrasp_render::{Camera, CameraConfig, RenderError, Renderer};
use fairgrasp_sim::rapier3d::na::{Isometry3, Point3, Vector3};
use fairgrasp_sim::scene::Scene;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// What the policy observes (ManiSkill's `obs_mode`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ObsMode {
    /// The task's observation vector (object pose included); no images.
    #[default]
    #[serde(rename = "state")]
    State,
    /// RGB images (3 bytes a pixel) and the arm's readings.
    #[serde(rename = "rgb+state")]
    RgbState,
    /// Depth images (1 byte a pixel, `camera.near`..`camera.far` in 255 steps) and the arm's
    /// readings.
    #[serde(rename = "depth+state")]
    DepthState,
    /// RGB and depth in one image (4 bytes a pixel) and the arm's readings.
    #[serde(rename = "rgbd+state")]
    RgbdState,
}

impl ObsMode {
    /// Every mode, in the order the docs list them.
    pub const ALL: [ObsMode; 4] = [
        ObsMode::State,
        ObsMode::RgbState,
        ObsMode::DepthState,
        ObsMode::RgbdState,
    ];

    /// The name configs, the CLI and Python use (`rgb+state`).
    pub fn name(self) -> &'static str {
        match self {
            ObsMode::State => "state",
            ObsMode::RgbState => "rgb+state",
            ObsMode::DepthState => "depth+state",
            ObsMode::RgbdState => "rgbd+state",
        }
    }

    /// Whether observations carry images.
    pub fn has_images(self) -> bool {
        self != ObsMode::State
    }

    /// Bytes per pixel (0 without images).
    pub fn channels(self) -> u32 {
        match self {
            ObsMode::State => 0,
            ObsMode::RgbState => 3,
            ObsMode::DepthState => 1,
            ObsMode::RgbdState => 4,
        }
    }

    /// The suffix of the image keys (`scene_rgb`).
    fn image_kind(self) -> &'static str {
        match self {
            ObsMode::State => "",
            ObsMode::RgbState => "rgb",
            ObsMode::DepthState => "depth",
            ObsMode::RgbdState => "rgbd",
        }
    }
}

impl fmt::Display for ObsMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ObsMode {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        ObsMode::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                let names: Vec<_> = ObsMode::ALL.iter().map(|m| m.name()).collect();
                format!("unknown observation mode {s:?}; expected one of {names:?}")
            })
    }
}

/// A camera fixed in the scene, looking at a point.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SceneCameraConfig {
    /// Whether the images include this camera's.
    pub enabled: bool,
    /// Camera position in the world (m).
    pub eye: [f32; 3],
    /// The point the optical axis passes through (m).
    pub target: [f32; 3],
    /// World direction that appears upward in the image.
    pub up: [f32; 3],
    /// Vertical field of view (degrees).
    pub fov_deg: f32,
}

impl Default for SceneCameraConfig {
    /// In front of the table, above the object's area, looking down at it at about 50°: the
    /// whole placement area and the gripper above it are in view.
    fn default() -> Self {
        Self {
            enabled: true,
            eye: [1.05, 0.0, 1.45],
            target: [0.45, 0.0, 0.78],
            up: [0.0, 0.0, 1.0],
            fov_deg: 50.0,
        }
    }
}

/// A camera on the flange, moving with the gripper and looking along the tool's approach axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WristCameraConfig {
    /// Whether the images include this camera's.
    pub enabled: bool,
    /// Camera position in the TCP frame (m; z along the approach, y the fingers' travel).
    pub offset: [f32; 3],
    /// Vertical field of view (degrees).
    pub fov_deg: f32,
}

impl Default for WristCameraConfig {
    /// Beside the fingers (8 cm off the tool axis, across their travel), 12 cm behind the TCP.
    fn default() -> Self {
        Self {
            enabled: false,
            offset: [0.08, 0.0, -0.12],
            fov_deg: 70.0,
        }
    }
}

/// The `[camera]` section: observation mode and the cameras behind it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraObsConfig {
    /// What the policy observes.
    pub mode: ObsMode,
    /// Image width of every camera (pixels).
    pub width: u32,
    /// Image height of every camera (pixels).
    pub height: u32,
    /// Nearest drawn distance, and depth byte 0 (m).
    pub near: f32,
    /// Farthest drawn distance, and depth byte 255 (m).
    pub far: f32,
    /// The fixed scene camera.
    pub scene: SceneCameraConfig,
    /// The wrist camera.
    pub wrist: WristCameraConfig,
}

impl Default for CameraObsConfig {
    fn default() -> Self {
        Self {
            mode: ObsMode::State,
            width: 64,
            height: 64,
            near: 0.02,
            far: 2.5,
            scene: SceneCameraConfig::default(),
            wrist: WristCameraConfig::default(),
        }
    }
}

/// Image sides a camera observation may have (pixels): below 16 an object is a pixel or two;
/// above 512 one step's images outweigh the rest of a rollout.
pub const IMAGE_SIDES: [u32; 2] = [16, 512];

/// `RenderError::Camera` with the key under `camera.<view>`.
fn camera_key(view: &str, e: RenderError) -> EnvError {
    match e {
        RenderError::Camera { field, problem } => {
            EnvError::config(format!("camera.{view}.{field}"), problem)
        }
        other => EnvError::Render(other),
    }
}

impl CameraObsConfig {
    /// Checks sizes, the depth range and each enabled camera; errors name the key.
    pub fn validate(&self) -> Result<()> {
        for (key, side) in [("camera.width", self.width), ("camera.height", self.height)] {
            if !(IMAGE_SIDES[0]..=IMAGE_SIDES[1]).contains(&side) {
                return Err(EnvError::config(
                    key,
                    format!(
                        "must be {} to {} pixels, got {side}",
                        IMAGE_SIDES[0], IMAGE_SIDES[1]
                    ),
                ));
            }
        }
        if !(self.near.is_finite() && self.near >= 1e-3 && self.near <= 10.0) {
            return Err(EnvError::config(
                "camera.near",
                format!("must be 0.001 to 10 m, got {}", self.near),
            ));
        }
        if !(self.far.is_finite() && self.far > self.near && self.far <= 100.0) {
            return Err(EnvError::config(
                "camera.far",
                format!(
                    "must be larger than camera.near ({}) and at most 100 m, got {}",
                    self.near, self.far
                ),
            ));
        }
        if self.mode.has_images() && !self.scene.enabled && !self.wrist.enabled {
            return Err(EnvError::config(
                "camera.mode",
                format!(
                    "{} needs a camera: set camera.scene.enabled or camera.wrist.enabled",
                    self.mode
                ),
            ));
        }
        Camera::new(self.scene_camera()).map_err(|e| camera_key("scene", e))?;
        if !self.wrist.offset.iter().all(|v| v.is_finite()) {
            return Err(EnvError::config(
                "camera.wrist.offset",
                format!("{:?} is not finite", self.wrist.offset),
            ));
        }
        Camera::new(self.wrist_camera(&Isometry3::identity()))
            .map_err(|e| camera_key("wrist", e))?;
        Ok(())
    }

    fn scene_camera(&self) -> CameraConfig {
        let s = &self.scene;
        CameraConfig {
            eye: s.eye,
            target: s.target,
            up: s.up,
            fov_deg: s.fov_deg,
            width: self.width,
            height: self.height,
            near: self.near,
            far: self.far,
        }
    }

    /// The wrist camera when the TCP is at `tcp`: at the offset, looking along the tool's z,
    /// with the tool's x up in the image.
    fn wrist_camera(&self, tcp: &Isometry3<f64>) -> CameraConfig {
        let [x, y, z] = self.wrist.offset.map(f64::from);
        let eye = tcp * Point3::new(x, y, z);
        let target = eye + tcp.rotation * Vector3::z();
        let up = tcp.rotation * Vector3::x();
        let f = |v: [f64; 3]| v.map(|c| c as f32);
        CameraConfig {
            eye: f([eye.x, eye.y, eye.z]),
            target: f([target.x, target.y, target.z]),
            up: f([up.x, up.y, up.z]),
            fov_deg: self.wrist.fov_deg,
            width: self.width,
            height: self.height,
            near: self.near,
            far: self.far,
        }
    }
}

/// Where a view's camera is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mount {
    Scene,
    Wrist,
}

/// The cameras of a pixel observation and the buffer their images are drawn into.
pub struct Cameras {
    config: CameraObsConfig,
    views: Vec<(Mount, Renderer)>,
    space: ImageSpace,
    image: Vec<u8>,
}

impl Cameras {
    /// The cameras `config` enables for `scene`; `None` in [`ObsMode::State`].
    pub fn new(config: &CameraObsConfig, scene: &Scene) -> Result<Option<Self>> {
        if !config.mode.has_images() {
            return Ok(None);
        }
        let mut views = Vec::new();
        let mut space = ImageSpace::default();
        let mounts = [
            (Mount::Scene, "scene", config.scene.enabled),
            (Mount::Wrist, "wrist", config.wrist.enabled),
        ];
        for (mount, name, enabled) in mounts {
            if !enabled {
                continue;
            }
            let camera = match mount {
                Mount::Scene => config.scene_camera(),
                Mount::Wrist => config.wrist_camera(&scene.tcp_pose()),
            };
            let camera = Camera::new(camera).map_err(|e| camera_key(name, e))?;
            views.push((mount, Renderer::new(scene, camera)?));
            space.views.push(ImageView {
                name: format!("{name}_{}", config.mode.image_kind()),
                height: config.height,
                width: config.width,
                channels: config.mode.channels(),
            });
        }
        Ok(Some(Self {
            image: vec![0; space.len()],
            config: config.clone(),
            views,
            space,
        }))
    }

    /// The images' layout.
    pub fn space(&self) -> &ImageSpace {
        &self.space
    }

    /// The images drawn last ([`ImageSpace::len`] bytes).
    pub fn image(&self) -> &[u8] {
        &self.image
    }

    /// Draws every view of the scene as it is now.
    pub fn capture(&mut self, scene: &Scene) -> Result<()> {
        let mode = self.config.mode;
        let (near, far) = (self.config.near, self.config.far);
        let mut start = 0;
        for (i, (mount, renderer)) in self.views.iter_mut().enumerate() {
            if *mount == Mount::Wrist {
                let camera = Camera::new(self.config.wrist_camera(&scene.tcp_pose()))
                    .map_err(|e| camera_key("wrist", e))?;
                renderer.set_camera(camera);
            }
            renderer.render(scene)?;
            let out = &mut self.image[start..start + self.space.views[i].len()];
            start += out.len();
            let depth_byte = |d: f32| {
                ((d - near) / (far - near) * 255.0)
                    .round()
                    .clamp(0.0, 255.0) as u8
            };
            match mode {
                ObsMode::State => {}
                ObsMode::RgbState => out.copy_from_slice(renderer.rgb()),
                ObsMode::DepthState => {
                    for (o, d) in out.iter_mut().zip(renderer.depth()) {
                        *o = depth_byte(*d);
                    }
                }
                ObsMode::RgbdState => {
                    let pixels = renderer.rgb().chunks_exact(3).zip(renderer.depth());
                    for (o, (rgb, d)) in out.chunks_exact_mut(4).zip(pixels) {
                        o[..3].copy_from_slice(rgb);
                        o[3] = depth_byte(*d);
                    }
                }
            }
        }
        Ok(())
    }
}
