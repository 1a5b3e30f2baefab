//! Animated GIFs from rendered RGB frames: `fairgrasp record` and the evaluation videos of a
//! training run (`eval.record`). The `gif` crate encodes; each frame gets its own palette
//! (NeuQuant at speed 10: 2–3 ms per 320×240 frame).

use crate::error::{RenderError, Result};

/// An endlessly looping GIF of `frames` (`height × width × 3` sRGB bytes each) at `fps`
/// (GIF delays are whole hundredths of a second: 30 fps plays at 33 fps).
pub fn encode_gif(frames: &[Vec<u8>], width: u32, height: u32, fps: f32) -> Result<Vec<u8>> {
    let bad = |problem: String| RenderError::Video(problem);
    let (w, h) = (
        u16::try_from(width).map_err(|_| bad(format!("width {width} exceeds a GIF's 65535")))?,
        u16::try_from(height).map_err(|_| bad(format!("height {height} exceeds a GIF's 65535")))?,
    );
    if frames.is_empty() {
        return Err(bad("no frames".into()));
    }
    let expected = width as usize * height as usize * 3;
    if let Some(i) = frames.iter().position(|f| f.len() != expected) {
        return Err(bad(format!(
            "frame {i} has {} bytes, a {width}×{height} RGB frame has {expected}",
            frames[i].len()
        )));
    }
    let gif_error = |e: gif::EncodingError| bad(e.to_string());
    let mut bytes = Vec::new();
    {
        let mut encoder = gif::Encoder::new(&mut bytes, w, h, &[]).map_err(gif_error)?;
        encoder
            .set_repeat(gif::Repeat::Infinite)
            .map_err(gif_error)?;
        let delay = (100.0 / fps.max(1.0)).round().max(2.0) as u16;
        for rgb in frames {
            let mut frame = gif::Frame::from_rgb_speed(w, h, rgb, 10);
            frame.delay = delay;
            encoder.write_frame(&frame).map_err(gif_error)?;
        }
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_come_back_in_order_and_bad_frames_are_refused() {
        let (w, h) = (8u32, 4u32);
        let frames: Vec<Vec<u8>> = (0..3u8)
            .map(|k| vec![k * 100; (w * h * 3) as usize])
            .collect();
        let bytes = encode_gif(&frames, w, h, 30.0).unwrap();
        let mut options = gif::DecodeOptions::new();
        options.set_color_output(gif::ColorOutput::RGBA);
        let mut decoder = options.read_info(bytes.as_slice()).unwrap();
        let mut reds = Vec::new();
        while let Some(frame) = decoder.read_next_frame().unwrap() {
            assert_eq!(frame.delay, 3);
            reds.push(frame.buffer[0]);
        }
        assert_eq!(reds.len(), 3);
        assert!(reds[0] < reds[1] && reds[1] < reds[2], "{reds:?}");
        let short = vec![vec![0u8; 5]];
        assert!(
            encode_gif(&short, w, h, 30.0)
                .unwrap_err()
                .to_string()
                .contains("frame 0 has 5 bytes")
        );
        assert!(encode_gif(&[], w, h, 30.0).is_err());
    }
}
