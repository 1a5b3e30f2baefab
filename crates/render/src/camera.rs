//! A pinhole camera: where it is, where it looks, its field of view and its image size.
//!
//! Camera frame as in OpenCV: x to the right of the image, y down, z forward (the optical
//! axis). Pixel `(u, v)` has its centre at `(u + 0.5, v + 0.5)`; row 0 is the top.

use crate::error::{RenderError, Result};
use fairgrasp_sim::rapier3d::math::Vector;
use serde::{Deserialize, Serialize};

/// Largest image side (pixels): a typo such as 64000 should be an error, not 12 GB of buffers.
pub const MAX_SIDE: u32 = 8192;

/// Camera settings as written in a config: a look-at pose, a vertical field of view and an
/// image size. [`Camera::new`] checks them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    /// Camera position in the world (m).
    pub eye: [f32; 3],
    /// The point the optical axis passes through (m).
    pub target: [f32; 3],
    /// World direction that appears upward in the image (need not be exactly orthogonal).
    pub up: [f32; 3],
    /// Vertical field of view (degrees), in (0, 170].
    pub fov_deg: f32,
    /// Image width (pixels), 1 to [`MAX_SIDE`].
    pub width: u32,
    /// Image height (pixels), 1 to [`MAX_SIDE`].
    pub height: u32,
    /// Nothing nearer than this is drawn (m).
    pub near: f32,
    /// Nothing farther is drawn; background depth reads this (m).
    pub far: f32,
}

impl Default for CameraConfig {
    /// A front-three-quarter view of the default table, arm and placement area, 640×480.
    fn default() -> Self {
        Self::front_three_quarter(640, 480)
    }
}

impl CameraConfig {
    /// The default view at another resolution.
    pub fn front_three_quarter(width: u32, height: u32) -> Self {
        Self {
            eye: [1.45, -0.95, 1.45],
            target: [0.35, 0.0, 0.85],
            up: [0.0, 0.0, 1.0],
            fov_deg: 45.0,
            width,
            height,
            near: 0.05,
            far: 10.0,
        }
    }

    /// Looking straight down on the placement area: world +x points up the image, +y left.
    pub fn top_down(width: u32, height: u32) -> Self {
        Self {
            eye: [0.45, 0.0, 2.1],
            target: [0.45, 0.0, 0.75],
            up: [1.0, 0.0, 0.0],
            fov_deg: 45.0,
            width,
            height,
            near: 0.05,
            far: 10.0,
        }
    }
}

/// A checked camera with its precomputed frame and intrinsics.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    config: CameraConfig,
    eye: Vector,
    /// World directions of the camera axes (x right, y down, z forward).
    right: Vector,
    down: Vector,
    forward: Vector,
    /// Focal length in pixels (square pixels).
    focal: f32,
}

fn finite3(field: &'static str, v: [f32; 3]) -> Result<Vector> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(Vector::from(v))
    } else {
        Err(RenderError::camera(field, format!("{v:?} is not finite")))
    }
}

impl Camera {
    /// Checks the settings: finite positions, eye ≠ target, `up` not along the view direction,
    /// field of view in (0°, 170°], image sides 1 to [`MAX_SIDE`], 0 < near < far.
    pub fn new(config: CameraConfig) -> Result<Self> {
        let eye = finite3("eye", config.eye)?;
        let target = finite3("target", config.target)?;
        let up = finite3("up", config.up)?;
        let view = target - eye;
        if view.length() < 1e-6 {
            return Err(RenderError::camera(
                "target",
                "coincides with the eye; the camera has no direction",
            ));
        }
        let forward = view.normalize();
        let right = forward.cross(up);
        if up.length() < 1e-6 || right.length() < 1e-4 * up.length() {
            return Err(RenderError::camera(
                "up",
                format!("{:?} is zero or along the view direction", config.up),
            ));
        }
        let right = right.normalize();
        let down = forward.cross(right);
        if !(config.fov_deg.is_finite() && config.fov_deg > 0.0 && config.fov_deg <= 170.0) {
            return Err(RenderError::camera(
                "fov_deg",
                format!("must be in (0, 170] degrees, got {}", config.fov_deg),
            ));
        }
        for (field, side) in [("width", config.width), ("height", config.height)] {
            if side == 0 || side > MAX_SIDE {
                return Err(RenderError::camera(
                    field,
                    format!("must be 1 to {MAX_SIDE} pixels, got {side}"),
                ));
            }
        }
        if !(config.near.is_finite() && config.near > 0.0) {
            return Err(RenderError::camera(
                "near",
                format!("must be positive, got {}", config.near),
            ));
        }
        if !(config.far.is_finite() && config.far > config.near) {
            return Err(RenderError::camera(
                "far",
                format!(
                    "must be larger than near ({}), got {}",
                    config.near, config.far
                ),
            ));
        }
        let focal = config.height as f32 / 2.0 / (config.fov_deg.to_radians() / 2.0).tan();
        Ok(Self {
            config,
            eye,
            right,
            down,
            forward,
            focal,
        })
    }

    /// The settings it was built from.
    pub fn config(&self) -> &CameraConfig {
        &self.config
    }

    /// Image width (pixels).
    pub fn width(&self) -> u32 {
        self.config.width
    }

    /// Image height (pixels).
    pub fn height(&self) -> u32 {
        self.config.height
    }

    /// Near clipping distance along the optical axis (m).
    pub fn near(&self) -> f32 {
        self.config.near
    }

    /// Far clipping distance along the optical axis (m): the depth the background reads.
    pub fn far(&self) -> f32 {
        self.config.far
    }

    /// Camera position in the world.
    pub fn eye(&self) -> Vector {
        self.eye
    }

    /// Focal length (pixels).
    pub fn focal(&self) -> f32 {
        self.focal
    }

    /// A world point in the camera frame (x right, y down, z forward; m).
    pub fn to_camera(&self, world: Vector) -> Vector {
        let d = world - self.eye;
        Vector::new(d.dot(self.right), d.dot(self.down), d.dot(self.forward))
    }

    /// A world direction in the camera frame.
    pub fn direction_to_camera(&self, world: Vector) -> Vector {
        Vector::new(
            world.dot(self.right),
            world.dot(self.down),
            world.dot(self.forward),
        )
    }

    /// Image coordinates (pixels, continuous: pixel `(u, v)` spans `[u, u+1) × [v, v+1)`) of a
    /// camera-frame point with z > 0.
    pub fn project_camera(&self, p: Vector) -> (f32, f32) {
        let cx = self.config.width as f32 / 2.0;
        let cy = self.config.height as f32 / 2.0;
        (self.focal * p.x / p.z + cx, self.focal * p.y / p.z + cy)
    }

    /// Where a world point appears: `(u, v, depth)` with `depth` its distance along the optical
    /// axis (m), or `None` when it is behind the near plane. `u`, `v` may lie outside the image.
    pub fn project(&self, world: Vector) -> Option<(f32, f32, f32)> {
        let p = self.to_camera(world);
        if p.z < self.config.near {
            return None;
        }
        let (u, v) = self.project_camera(p);
        Some((u, v, p.z))
    }

    /// The pixel `(column, row)` a world point falls in, if it is in the image and in front.
    pub fn pixel_of(&self, world: Vector) -> Option<(u32, u32)> {
        let (u, v, _) = self.project(world)?;
        let inside =
            u >= 0.0 && v >= 0.0 && u < self.config.width as f32 && v < self.config.height as f32;
        inside.then_some((u as u32, v as u32))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_target_projects_to_the_image_centre_at_its_distance() {
        let c = Camera::new(CameraConfig::default()).unwrap();
        let (u, v, d) = c.project(Vector::from(c.config().target)).unwrap();
        assert!(
            (u - 320.0).abs() < 1e-3 && (v - 240.0).abs() < 1e-3,
            "{u} {v}"
        );
        let expected = (Vector::from(c.config().target) - c.eye()).length();
        assert!((d - expected).abs() < 1e-4);
        // World up appears upward (smaller row) in the image.
        let above = Vector::from(c.config().target) + Vector::new(0.0, 0.0, 0.1);
        assert!(c.project(above).unwrap().1 < 240.0);
    }

    #[test]
    fn bad_settings_are_errors_naming_the_field() {
        let bad = |f: fn(&mut CameraConfig), field: &str| {
            let mut c = CameraConfig::default();
            f(&mut c);
            let e = Camera::new(c).unwrap_err().to_string();
            assert!(e.contains(field), "{e}");
        };
        bad(|c| c.fov_deg = 0.0, "fov_deg");
        bad(|c| c.fov_deg = f32::NAN, "fov_deg");
        bad(|c| c.width = 0, "width");
        bad(|c| c.height = MAX_SIDE + 1, "height");
        bad(|c| c.target = c.eye, "target");
        bad(|c| c.eye[0] = f32::INFINITY, "eye");
        bad(|c| c.up = [0.0; 3], "up");
        bad(|c| c.near = 0.0, "near");
        bad(|c| c.far = 0.01, "far");
        let mut along = CameraConfig::top_down(8, 8);
        along.up = [0.0, 0.0, 1.0];
        assert!(Camera::new(along).unwrap_err().to_string().contains("up"));
    }
}
