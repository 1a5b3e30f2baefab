//! fairgrasp-render: draws the grasp scene on the CPU (no display, no GPU) into RGB, depth and
//! segmentation images, fast enough to serve as an observation.
//!
//! Layer between the simulation and the environment (sim → render → env):
//! - `camera.rs`: [`Camera`] and its settings [`CameraConfig`], with default views;
//! - `mesh.rs`: tessellation of collider shapes and URDF geometries;
//! - `scene_mesh.rs`: what to draw of a [`fairgrasp_sim::scene::Scene`], meshes cached;
//! - `raster.rs`: the z-buffer rasteriser (flat Lambert shading);
//! - `segment.rs`: the segmentation id table;
//! - `renderer.rs`: [`Renderer`], tying them together;
//! - `image.rs`: PNG output and false-colour views.
//!
//! ```no_run
//! use fairgrasp_render::{CameraConfig, Renderer};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut scene = fairgrasp_sim::scene::Scene::new(Default::default())?;
//! scene.reset(0)?;
//! let mut renderer = Renderer::with_config(&scene, CameraConfig::front_three_quarter(84, 84))?;
//! renderer.render(&scene)?;
//! let (rgb, depth, ids) = (renderer.rgb(), renderer.depth(), renderer.segmentation());
//! # let _ = (rgb, depth, ids); Ok(()) }
//! ```

#![warn(missing_docs)]

pub mod camera;
pub mod error;
pub mod image;
pub mod mesh;
pub mod raster;
pub mod renderer;
pub mod scene_mesh;
pub mod segment;
pub mod video;

pub use camera::{Camera, CameraConfig};
pub use error::{RenderError, Result};
pub use renderer::{Look, Renderer, segment_name};
pub use segment::Segment;
