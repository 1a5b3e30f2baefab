//! Writes what the default camera sees of a reset scene: `snapshot [OUT_DIR] [SEED]` →
//! `scene.png`, `depth.png`, `segmentation.png`, `top.png`.

use fairgrasp_render::image::{depth_to_rgb, segmentation_to_rgb, write_png};
use fairgrasp_render::{CameraConfig, Renderer};
use fairgrasp_sim::scene::{Scene, SceneConfig};
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(args.next().unwrap_or_else(|| ".".into()));
    let seed = args.next().map(|s| s.parse()).transpose()?.unwrap_or(0);
    let mut scene = Scene::new(SceneConfig::default())?;
    scene.reset(seed)?;
    let mut r = Renderer::with_config(&scene, CameraConfig::default())?;
    r.render(&scene)?;
    let (w, h) = (r.width(), r.height());
    write_png(&dir.join("scene.png"), w, h, r.rgb())?;
    let depth = depth_to_rgb(r.depth(), 1.0, 2.5);
    write_png(&dir.join("depth.png"), w, h, &depth)?;
    write_png(
        &dir.join("segmentation.png"),
        w,
        h,
        &segmentation_to_rgb(r.segmentation()),
    )?;
    let mut top = Renderer::with_config(&scene, CameraConfig::top_down(w, h))?;
    top.render(&scene)?;
    write_png(&dir.join("top.png"), w, h, top.rgb())?;
    Ok(())
}
