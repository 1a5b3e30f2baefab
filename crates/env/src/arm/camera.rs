//! Camera observations (`[camera]`): the images a pixel policy sees beside the arm's own
//! readings, drawn after every reset and step by the CPU renderer.
//!
//! In a pixel mode the state vector is what the real arm reports (joints, speeds, TCP, gripper,
//! the previous action), never the object's pose; the task's full observation, as a state policy
//! of the same settings reads it (through `[readings]` when they are on), goes to
//! [`crate::core::Info::privileged`] for a critic that sees it (asymmetric actor-critic) and for
//! a distillation's teacher.

use crate::config::check_range;
use crate::error::{EnvError, Result};
use crate::random::uniform;
use crate::spaces::{ImageSpace, ImageView};
use fairgrasp_render::{Camera, CameraConfig, Look, RenderError, Renderer};
use fairgrasp_sim::rapier3d::na::{Isometry3, Point3, Vector3};
use fairgrasp_sim::scene::Scene;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
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

/// `[camera.randomize]`: visual domain randomisation, drawn per episode (the noise per frame).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VisualRandomization {
    /// Whether anything is drawn (off: every episode looks as designed).
    pub enabled: bool,
    /// Direction toward the light around the vertical (degrees; 0 = +x).
    pub light_azimuth_deg: [f32; 2],
    /// The light's height above the horizon (degrees).
    pub light_elevation_deg: [f32; 2],
    /// Scale of every lit colour.
    pub brightness: [f32; 2],
    /// Per-channel scale of the table's, the objects' and the robot's colours (each drawn
    /// apart).
    pub tint: [f32; 2],
    /// Per-channel scale of the background's colour.
    pub background: [f32; 2],
    /// Each camera's position moves by up to this much along each axis (m).
    pub position_jitter: f32,
    /// Each camera's view direction turns by up to this angle (degrees).
    pub angle_jitter_deg: f32,
    /// Each camera's field of view changes by up to this much (degrees).
    pub fov_jitter_deg: f32,
    /// Standard deviation of each pixel's noise (levels of 255), uniform, drawn every frame.
    pub pixel_noise: f32,
}

impl Default for VisualRandomization {
    /// The ranges the issue names for the camera (±2 cm, ±3°) and lighting and colour changes
    /// a lab sees over a day.
    fn default() -> Self {
        Self {
            enabled: false,
            light_azimuth_deg: [-180.0, 180.0],
            light_elevation_deg: [35.0, 85.0],
            brightness: [0.75, 1.25],
            tint: [0.8, 1.2],
            background: [0.8, 1.1],
            position_jitter: 0.02,
            angle_jitter_deg: 3.0,
            fov_jitter_deg: 3.0,
            pixel_noise: 3.0,
        }
    }
}

impl VisualRandomization {
    fn validate(&self) -> Result<()> {
        let key = |k: &str| format!("camera.randomize.{k}");
        check_range(
            &key("light_azimuth_deg"),
            self.light_azimuth_deg,
            -360.0,
            360.0,
        )?;
        check_range(
            &key("light_elevation_deg"),
            self.light_elevation_deg,
            0.0,
            90.0,
        )?;
        check_range(&key("brightness"), self.brightness, 0.05, 5.0)?;
        check_range(&key("tint"), self.tint, 0.0, 5.0)?;
        check_range(&key("background"), self.background, 0.0, 2.0)?;
        let limits = [
            ("position_jitter", self.position_jitter, 0.5),
            ("angle_jitter_deg", self.angle_jitter_deg, 45.0),
            ("fov_jitter_deg", self.fov_jitter_deg, 45.0),
            ("pixel_noise", self.pixel_noise, 100.0),
        ];
        for (name, value, max) in limits {
            if !(value.is_finite() && (0.0..=max).contains(&value)) {
                return Err(EnvError::config(
                    key(name),
                    format!("must be 0 to {max}, got {value}"),
                ));
            }
        }
        Ok(())
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
    /// Visual domain randomisation.
    pub randomize: VisualRandomization,
    /// How many control steps old the images are: drawn per episode from this range
    /// (inclusive). A camera's frame reaches a real loop after its exposure, readout and
    /// transfer (the twin's camera: 40 ms, plus up to a 33 ms frame period): one to two
    /// 33 ms control steps at speed scale 1. Images before the episode's first show its first.
    pub delay_steps: [u32; 2],
}

/// The longest image delay accepted (control steps).
pub const MAX_DELAY_STEPS: u32 = 8;

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
            randomize: VisualRandomization::default(),
            delay_steps: [0, 0],
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
        let [lo, hi] = self.delay_steps;
        if lo > hi || hi > MAX_DELAY_STEPS {
            return Err(EnvError::config(
                "camera.delay_steps",
                format!(
                    "must be [low, high] with low <= high <= {MAX_DELAY_STEPS}, got [{lo}, {hi}]"
                ),
            ));
        }
        self.randomize.validate()
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
        self.wrist_camera_at(tcp, &Jitter::default())
    }

    /// [`Self::wrist_camera`] with its mounting moved by `jitter`.
    fn wrist_camera_at(&self, tcp: &Isometry3<f64>, jitter: &Jitter) -> CameraConfig {
        let offset: [f32; 3] = std::array::from_fn(|i| self.wrist.offset[i] + jitter.position[i]);
        let [x, y, z] = offset.map(f64::from);
        let eye = tcp * Point3::new(x, y, z);
        let [tx, ty, tz] = jitter.turn.map(f64::from);
        let target = eye + tcp.rotation * (Vector3::z() + Vector3::new(tx, ty, tz));
        let up = tcp.rotation * Vector3::x();
        let f = |v: [f64; 3]| v.map(|c| c as f32);
        CameraConfig {
            eye: f([eye.x, eye.y, eye.z]),
            target: f([target.x, target.y, target.z]),
            up: f([up.x, up.y, up.z]),
            fov_deg: self.wrist.fov_deg + jitter.fov_deg,
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

/// One episode's change to a camera (visual domain randomisation).
#[derive(Clone, Debug, Default, PartialEq)]
struct Jitter {
    /// Added to the position (m; for the wrist camera, in the TCP frame).
    position: [f32; 3],
    /// Added to the unit view direction (turns it by about its length, in radians).
    turn: [f32; 3],
    /// Added to the field of view (degrees).
    fov_deg: f32,
}

/// The cameras of a pixel observation and the buffer their images are drawn into.
pub struct Cameras {
    config: CameraObsConfig,
    views: Vec<(Mount, Renderer, Jitter)>,
    space: ImageSpace,
    image: Vec<u8>,
    /// The images of the episode's last steps, newest last (while they are delayed).
    history: VecDeque<Vec<u8>>,
    /// This episode's delay (control steps).
    delay: usize,
    /// The stream of the visual randomisation (reseeded at every episode's start).
    rng: ChaCha8Rng,
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
            views.push((mount, Renderer::new(scene, camera)?, Jitter::default()));
            space.views.push(ImageView {
                name: format!("{name}_{}", config.mode.image_kind()),
                height: config.height,
                width: config.width,
                channels: config.mode.channels(),
            });
        }
        Ok(Some(Self {
            image: vec![0; space.len()],
            history: VecDeque::new(),
            delay: config.delay_steps[0] as usize,
            config: config.clone(),
            views,
            space,
            rng: ChaCha8Rng::seed_from_u64(0),
        }))
    }

    /// The images' layout.
    pub fn space(&self) -> &ImageSpace {
        &self.space
    }

    /// The images the policy sees now ([`ImageSpace::len`] bytes): those drawn last, or with
    /// `camera.delay_steps`, those of that many steps before.
    pub fn image(&self) -> &[u8] {
        if self.history.is_empty() {
            return &self.image;
        }
        let back = self.delay.min(self.history.len() - 1);
        &self.history[self.history.len() - 1 - back]
    }

    /// Whether the episode's start draws anything (visual randomisation, a delay from a
    /// range): then [`Self::start_episode`] wants a seed from the environment's stream.
    pub fn randomized(&self) -> bool {
        let [lo, hi] = self.config.delay_steps;
        self.config.randomize.enabled || lo < hi
    }

    /// Forgets the last episode's images, and with a `seed` (when [`Self::randomized`]) draws
    /// the episode's delay, look and camera changes from a stream seeded with it.
    pub fn start_episode(&mut self, seed: Option<u64>) -> Result<()> {
        self.history.clear();
        let Some(seed) = seed else {
            return Ok(());
        };
        let [lo, hi] = self.config.delay_steps;
        self.rng = ChaCha8Rng::seed_from_u64(seed);
        self.delay = if lo < hi {
            self.rng.random_range(lo..=hi) as usize
        } else {
            lo as usize
        };
        let r = self.config.randomize.clone();
        if !r.enabled {
            return Ok(());
        }
        let rng = &mut self.rng;
        let azimuth = uniform(rng, r.light_azimuth_deg).to_radians();
        let elevation = uniform(rng, r.light_elevation_deg).to_radians();
        let light = [
            elevation.cos() * azimuth.cos(),
            elevation.cos() * azimuth.sin(),
            elevation.sin(),
        ];
        let brightness = uniform(rng, r.brightness);
        let mut tint = || -> [f32; 3] { std::array::from_fn(|_| uniform(rng, r.tint)) };
        let (table_tint, object_tint, robot_tint) = (tint(), tint(), tint());
        let background = std::array::from_fn(|i| {
            let scale = uniform(rng, r.background);
            (fairgrasp_render::renderer::BACKGROUND_RGB[i] as f32 * scale).clamp(0.0, 255.0) as u8
        });
        let look = Look {
            light: Some(light),
            brightness,
            background,
            table_tint,
            object_tint,
            robot_tint,
        };
        let turn = r.angle_jitter_deg.to_radians();
        for (mount, renderer, jitter) in &mut self.views {
            *jitter = Jitter {
                position: std::array::from_fn(|_| {
                    uniform(rng, [-r.position_jitter, r.position_jitter])
                }),
                turn: std::array::from_fn(|_| uniform(rng, [-turn, turn])),
                fov_deg: uniform(rng, [-r.fov_jitter_deg, r.fov_jitter_deg]),
            };
            renderer.set_look(look.clone());
            if *mount == Mount::Scene {
                let mut camera = self.config.scene_camera();
                let distance = (0..3)
                    .map(|i| (camera.target[i] - camera.eye[i]).powi(2))
                    .sum::<f32>()
                    .sqrt();
                for i in 0..3 {
                    camera.eye[i] += jitter.position[i];
                    camera.target[i] += jitter.position[i] + jitter.turn[i] * distance;
                }
                camera.fov_deg += jitter.fov_deg;
                let camera = Camera::new(camera).map_err(|e| camera_key("scene", e))?;
                renderer.set_camera(camera);
            }
        }
        Ok(())
    }

    /// Draws every view of the scene as it is now.
    pub fn capture(&mut self, scene: &Scene) -> Result<()> {
        let mode = self.config.mode;
        let (near, far) = (self.config.near, self.config.far);
        let mut start = 0;
        for (i, (mount, renderer, jitter)) in self.views.iter_mut().enumerate() {
            if *mount == Mount::Wrist {
                let camera = Camera::new(self.config.wrist_camera_at(&scene.tcp_pose(), jitter))
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
        let noise = self.config.randomize.pixel_noise;
        if self.config.randomize.enabled && noise > 0.0 {
            // Uniform on [-a, a] has standard deviation a / √3.
            let a = noise * 3f32.sqrt();
            for v in &mut self.image {
                let n: f32 = self.rng.random_range(-a..=a);
                *v = (*v as f32 + n).round().clamp(0.0, 255.0) as u8;
            }
        }
        if self.config.delay_steps[1] > 0 {
            // The first image of an episode stands for the steps before it.
            let keep = self.delay + 1;
            let mut frame = if self.history.len() >= keep {
                self.history.pop_front().unwrap_or_default()
            } else {
                Vec::new()
            };
            frame.clear();
            frame.extend_from_slice(&self.image);
            self.history.push_back(frame);
        }
        Ok(())
    }
}
