//! A z-buffer triangle rasteriser with flat Lambert shading, writing colour, inverse depth and a
//! segmentation id per pixel.
//!
//! Written here rather than taken from a crate: `euc` (0.5), the pure-Rust software rasteriser
//! on crates.io, renders one colour target through generic shader pipelines and is rarely
//! released; we need an id buffer beside colour and metric depth from one pass, no windowing,
//! and a tight loop for 84×84 observations, which is less code than adapting its pipeline. What it does not do: textures, shadows, specular
//! highlights, smooth (per-vertex) shading, anti-aliasing, transparency, and clipping against
//! any plane but the near one (the screen bounds are applied per pixel). Faces turned away are
//! skipped on closed meshes only; others (meshes from user files need not be closed or
//! consistently wound) are drawn from both sides.

use crate::camera::Camera;
use crate::mesh::Mesh;
use fairgrasp_sim::rapier3d::math::{Pose, Vector};

/// Light reaching faces turned away from the light (0..1 of the base colour).
const AMBIENT: f32 = 0.35;
/// Light on faces turned fully toward it.
const DIFFUSE: f32 = 0.65;

/// Linear 0..1 → 8-bit sRGB.
pub fn encode_srgb(linear: f32) -> u8 {
    let c = linear.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// Entries of the linear → sRGB table: steps of 1/4095 stay within one 8-bit level.
const SRGB_STEPS: usize = 4096;

/// [`encode_srgb`] through a table: `powf` per triangle cost a third of a small frame.
fn encode_srgb_fast(linear: f32) -> u8 {
    static TABLE: std::sync::OnceLock<[u8; SRGB_STEPS]> = std::sync::OnceLock::new();
    let table = TABLE
        .get_or_init(|| std::array::from_fn(|i| encode_srgb(i as f32 / (SRGB_STEPS - 1) as f32)));
    // NaN clamps to 0 through the saturating cast.
    let i = (linear.clamp(0.0, 1.0) * (SRGB_STEPS - 1) as f32 + 0.5) as usize;
    table[i.min(SRGB_STEPS - 1)]
}

/// 0..1 sRGB → linear, for colours given as they should look (URDF materials).
pub fn decode_srgb(srgb: f32) -> f32 {
    let c = srgb.clamp(0.0, 1.0);
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// A projected vertex: pixel position and inverse depth.
#[derive(Clone, Copy)]
struct ScreenVertex {
    x: f32,
    y: f32,
    inv_z: f32,
}

/// The image buffers of one camera.
pub struct Raster {
    width: usize,
    height: usize,
    /// 3 bytes per pixel, rows top to bottom.
    pub rgb: Vec<u8>,
    /// 1 / depth; 0 where nothing was drawn. Larger is nearer.
    pub inv_depth: Vec<f32>,
    /// Segmentation id per pixel (see [`crate::segment`]), rows top to bottom;
    /// [`crate::segment::BACKGROUND`] where nothing was drawn.
    pub segmentation: Vec<u16>,
    /// Camera-frame vertices of the mesh being drawn.
    scratch: Vec<Vector>,
}

impl Raster {
    /// Buffers for a `width × height` image, all pixels black, background id, no depth.
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width: width as usize,
            height: height as usize,
            rgb: vec![0; 3 * n],
            inv_depth: vec![0.0; n],
            segmentation: vec![0; n],
            scratch: Vec::new(),
        }
    }

    /// Fills every pixel with the background.
    pub fn clear(&mut self, background: [u8; 3]) {
        for px in self.rgb.chunks_exact_mut(3) {
            px.copy_from_slice(&background);
        }
        self.inv_depth.fill(0.0);
        self.segmentation.fill(crate::segment::BACKGROUND);
    }

    /// Metric depth along the optical axis (m); `far` where nothing was drawn.
    pub fn depth_into(&self, far: f32, out: &mut Vec<f32>) {
        out.clear();
        out.extend(
            self.inv_depth
                .iter()
                .map(|&iz| if iz > 0.0 { 1.0 / iz } else { far }),
        );
    }

    /// Draws `mesh` placed at `pose` (world) in linear colour `colour` with id `id`.
    /// `light` is the unit direction toward the light in the camera frame.
    pub fn draw_mesh(
        &mut self,
        camera: &Camera,
        light: Vector,
        pose: &Pose,
        mesh: &Mesh,
        colour: [f32; 3],
        id: u16,
    ) {
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.clear();
        scratch.extend(
            mesh.vertices
                .iter()
                .map(|&v| camera.to_camera(pose.transform_point(v))),
        );
        let (near, far) = (camera.near(), camera.far());
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| scratch[i as usize]);
            if (a.z < near && b.z < near && c.z < near) || (a.z > far && b.z > far && c.z > far) {
                continue;
            }
            let normal = (b - a).cross(c - a);
            // The camera sits at the origin: `a` points from it to the face.
            if mesh.closed && normal.dot(a) >= 0.0 {
                continue;
            }
            let length = normal.length();
            if !(length > 0.0 && length.is_finite()) {
                continue;
            }
            // Face the camera (at the origin): both sides of a triangle are lit alike.
            let mut n = normal / length;
            if n.dot(a) > 0.0 {
                n = -n;
            }
            let shade = AMBIENT + DIFFUSE * n.dot(light).max(0.0);
            let rgb = colour.map(|c| encode_srgb_fast(c * shade));
            if a.z >= near && b.z >= near && c.z >= near {
                self.fill(camera, [a, b, c], rgb, id);
            } else {
                let (polygon, n) = clip_near([a, b, c], near);
                self.fill(camera, [polygon[0], polygon[1], polygon[2]], rgb, id);
                if n == 4 {
                    self.fill(camera, [polygon[0], polygon[2], polygon[3]], rgb, id);
                }
            }
        }
        self.scratch = scratch;
    }

    /// Rasterises one camera-frame triangle lying in front of the near plane.
    fn fill(&mut self, camera: &Camera, tri: [Vector; 3], rgb: [u8; 3], id: u16) {
        let project = |p: Vector| {
            let (x, y) = camera.project_camera(p);
            ScreenVertex {
                x,
                y,
                inv_z: 1.0 / p.z,
            }
        };
        let [s0, mut s1, mut s2] = tri.map(project);
        let mut area = edge(s0, s1, s2.x, s2.y);
        // Degenerate (a line or a point on screen) or not a number: nothing to fill.
        if area.is_nan() || area.abs() <= 1e-9 {
            return;
        }
        if area < 0.0 {
            std::mem::swap(&mut s1, &mut s2);
            area = -area;
        }
        // Pixels whose centres (x + 0.5, y + 0.5) may lie inside, clamped to the image.
        let (w, h) = (self.width as f32, self.height as f32);
        let min_x = (s0.x.min(s1.x).min(s2.x) - 0.5).ceil().clamp(0.0, w);
        let max_x = (s0.x.max(s1.x).max(s2.x) - 0.5)
            .floor()
            .clamp(-1.0, w - 1.0);
        let min_y = (s0.y.min(s1.y).min(s2.y) - 0.5).ceil().clamp(0.0, h);
        let max_y = (s0.y.max(s1.y).max(s2.y) - 0.5)
            .floor()
            .clamp(-1.0, h - 1.0);
        if min_x > max_x || min_y > max_y {
            return;
        }
        let (x0, x1) = (min_x as usize, max_x as usize);
        let (y0, y1) = (min_y as usize, max_y as usize);
        let inv_area = 1.0 / area;
        let (inv_near, inv_far) = (1.0 / camera.near(), 1.0 / camera.far());
        // Edge functions grow by these per pixel step in x.
        let (dx0, dx1, dx2) = (s1.y - s2.y, s2.y - s0.y, s0.y - s1.y);
        let px0 = x0 as f32 + 0.5;
        for y in y0..=y1 {
            let py = y as f32 + 0.5;
            // Recomputed per row so rounding does not accumulate down the triangle.
            let mut e0 = edge(s1, s2, px0, py);
            let mut e1 = edge(s2, s0, px0, py);
            let mut e2 = edge(s0, s1, px0, py);
            let row = y * self.width;
            for x in x0..=x1 {
                if e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0 {
                    let iz = (e0 * s0.inv_z + e1 * s1.inv_z + e2 * s2.inv_z) * inv_area;
                    let i = row + x;
                    if iz > self.inv_depth[i] && iz <= inv_near && iz >= inv_far {
                        self.inv_depth[i] = iz;
                        self.segmentation[i] = id;
                        self.rgb[3 * i..3 * i + 3].copy_from_slice(&rgb);
                    }
                }
                e0 += dx0;
                e1 += dx1;
                e2 += dx2;
            }
        }
    }
}

/// Twice the signed area of (a, b, p): positive when p is left of a→b in image coordinates.
fn edge(a: ScreenVertex, b: ScreenVertex, px: f32, py: f32) -> f32 {
    (b.x - a.x) * (py - a.y) - (b.y - a.y) * (px - a.x)
}

/// The part of a triangle in front of the plane z = `near`: 3 or 4 vertices, in order.
fn clip_near(tri: [Vector; 3], near: f32) -> ([Vector; 4], usize) {
    let mut out = [Vector::ZERO; 4];
    let mut n = 0;
    for i in 0..3 {
        let (cur, next) = (tri[i], tri[(i + 1) % 3]);
        let (cur_in, next_in) = (cur.z >= near, next.z >= near);
        if cur_in {
            out[n] = cur;
            n += 1;
        }
        if cur_in != next_in {
            let t = (near - cur.z) / (next.z - cur.z);
            out[n] = cur + (next - cur) * t;
            n += 1;
        }
    }
    (out, n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::CameraConfig;

    fn camera(w: u32, h: u32) -> Camera {
        Camera::new(CameraConfig {
            eye: [0.0, 0.0, 0.0],
            target: [1.0, 0.0, 0.0],
            up: [0.0, 0.0, 1.0],
            fov_deg: 90.0,
            width: w,
            height: h,
            near: 0.1,
            far: 10.0,
        })
        .unwrap()
    }

    /// A square facing the camera at distance `d`, half size `s`.
    fn square(d: f32, s: f32) -> Mesh {
        Mesh {
            vertices: vec![
                Vector::new(d, -s, -s),
                Vector::new(d, s, -s),
                Vector::new(d, s, s),
                Vector::new(d, -s, s),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            closed: false,
        }
    }

    #[test]
    fn nearer_surfaces_win_and_depth_is_metric() {
        let cam = camera(32, 32);
        let mut r = Raster::new(32, 32);
        r.clear([0, 0, 0]);
        let light = Vector::new(0.0, 0.0, -1.0);
        // Far square first, then a smaller near one in front of it.
        r.draw_mesh(&cam, light, &Pose::IDENTITY, &square(2.0, 3.0), [1.0; 3], 7);
        r.draw_mesh(&cam, light, &Pose::IDENTITY, &square(1.0, 0.1), [1.0; 3], 9);
        // And the far one again: it must not overwrite the near one.
        r.draw_mesh(&cam, light, &Pose::IDENTITY, &square(2.0, 3.0), [1.0; 3], 7);
        let centre = 16 * 32 + 16;
        assert_eq!(r.segmentation[centre], 9);
        let mut depth = Vec::new();
        r.depth_into(cam.far(), &mut depth);
        assert!((depth[centre] - 1.0).abs() < 1e-4, "{}", depth[centre]);
        // The far square overfills the 90° view at 2 m (±2 m): a corner pixel shows it.
        assert_eq!(r.segmentation[0], 7);
        assert!((depth[0] - 2.0).abs() < 1e-3);
        // Lit face-on: 1.0 linear → 255.
        assert_eq!(&r.rgb[3 * centre..3 * centre + 3], &[255, 255, 255]);
    }

    #[test]
    fn triangles_crossing_the_near_plane_are_clipped_not_dropped() {
        let cam = camera(16, 16);
        let mut r = Raster::new(16, 16);
        r.clear([0, 0, 0]);
        // A floor-like quad from behind the camera to 5 m ahead, below the eye.
        let floor = Mesh {
            vertices: vec![
                Vector::new(-1.0, -3.0, -0.5),
                Vector::new(5.0, -3.0, -0.5),
                Vector::new(5.0, 3.0, -0.5),
                Vector::new(-1.0, 3.0, -0.5),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            closed: false,
        };
        r.draw_mesh(&cam, Vector::Z, &Pose::IDENTITY, &floor, [0.5; 3], 3);
        // The bottom row sees the floor close by; the top half sees nothing.
        assert!(r.segmentation[15 * 16..].iter().all(|&s| s == 3));
        assert!(r.segmentation[..16 * 7].iter().all(|&s| s == 0));
    }

    #[test]
    fn skipping_back_faces_of_closed_meshes_draws_the_same_picture() {
        let cam = camera(48, 48);
        let cube = crate::mesh::tessellate_shape(
            fairgrasp_sim::rapier3d::prelude::SharedShape::cuboid(0.3, 0.2, 0.25).as_ref(),
        )
        .unwrap();
        assert!(cube.closed);
        let pose =
            Pose::translation(1.0, 0.05, -0.05) * Pose::rotation(Vector::new(0.4, 0.7, -0.3));
        let draw = |closed: bool| {
            let mut r = Raster::new(48, 48);
            r.clear([0, 0, 0]);
            let mesh = Mesh {
                closed,
                ..cube.clone()
            };
            r.draw_mesh(
                &cam,
                Vector::new(0.0, -0.6, -0.8),
                &pose,
                &mesh,
                [0.5; 3],
                5,
            );
            r
        };
        let (culled, both) = (draw(true), draw(false));
        assert_eq!(culled.segmentation, both.segmentation);
        assert!(culled.segmentation.iter().filter(|&&s| s == 5).count() > 60);
        for (a, b) in culled.inv_depth.iter().zip(&both.inv_depth) {
            assert!((a - b).abs() < 1e-5, "{a} {b}");
        }
    }

    #[test]
    fn srgb_round_trips_and_the_table_matches_the_formula() {
        for v in [0u8, 1, 10, 100, 200, 255] {
            assert_eq!(encode_srgb(decode_srgb(v as f32 / 255.0)), v);
        }
        for k in 0..=1000 {
            let c = k as f32 / 1000.0;
            let (exact, fast) = (encode_srgb(c), encode_srgb_fast(c));
            assert!(exact.abs_diff(fast) <= 1, "{c}: {exact} vs {fast}");
        }
        assert_eq!(encode_srgb_fast(f32::NAN), 0);
        assert_eq!(encode_srgb_fast(2.0), 255);
    }
}
