//! Writing frames to PNG files, and false-colour views of depth and segmentation for people.

use crate::error::{RenderError, Result};
use std::path::Path;

/// Writes `rgb` (`height × width × 3` bytes) as an 8-bit RGB PNG.
pub fn write_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<()> {
    let fail = |problem: String| RenderError::Write {
        path: path.to_path_buf(),
        problem,
    };
    if rgb.len() != width as usize * height as usize * 3 {
        return Err(fail(format!(
            "{} bytes is not a {width}×{height} RGB image",
            rgb.len()
        )));
    }
    let file = std::fs::File::create(path).map_err(|e| fail(e.to_string()))?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::High);
    let mut writer = encoder.write_header().map_err(|e| fail(e.to_string()))?;
    writer
        .write_image_data(rgb)
        .map_err(|e| fail(e.to_string()))?;
    writer.finish().map_err(|e| fail(e.to_string()))
}

/// Depth as grey levels: near white, far (and background at `far`) black.
pub fn depth_to_rgb(depth: &[f32], near: f32, far: f32) -> Vec<u8> {
    let range = (far - near).max(f32::EPSILON);
    depth
        .iter()
        .flat_map(|&d| {
            let g = (255.0 * (1.0 - ((d - near) / range).clamp(0.0, 1.0))) as u8;
            [g, g, g]
        })
        .collect()
}

/// Segmentation ids as distinct colours (background black).
pub fn segmentation_to_rgb(ids: &[u16]) -> Vec<u8> {
    ids.iter()
        .flat_map(|&id| {
            if id == 0 {
                return [0, 0, 0];
            }
            // A multiplicative hash spreads neighbouring ids over the colour cube.
            let h = (id as u32).wrapping_mul(2_654_435_761);
            [
                (h >> 24) as u8 | 0x40,
                (h >> 16) as u8 | 0x40,
                (h >> 8) as u8 | 0x40,
            ]
        })
        .collect()
}
