//! `fairgrasp record`: episodes of a trained policy (or a random one) as an animated GIF, each
//! frame from the CPU renderer with a small overlay: episode, step, return so far, success.

use crate::eval_cmd::{check_frame_size, policy_and_env};
use anyhow::{Context, Result, bail};
use fairgrasp_env::core::{Env, Frame};
use fairgrasp_env::registry;
use fairgrasp_env::wrappers::RescaleAction;
use fairgrasp_rl::train::HELD_OUT_SEED_BASE;
use plotters::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct RecordArgs {
    /// The environment (default: the model's, else FaArmGrasp-v0).
    #[arg(long = "env")]
    pub id: Option<String>,
    /// A saved model; without one, actions are drawn uniformly from the action space.
    #[arg(long)]
    pub model: Option<PathBuf>,
    #[arg(long, default_value_t = 3)]
    pub episodes: u32,
    /// First episode seed (episode k uses seed + k); held-out by default.
    #[arg(long, default_value_t = HELD_OUT_SEED_BASE)]
    pub seed: u64,
    /// Where to write: `.gif`, or `.mp4` (needs ffmpeg on the PATH).
    #[arg(long, default_value = "episodes.gif")]
    pub out: PathBuf,
    /// Frame size (the `[render]` camera's width and height).
    #[arg(long, default_value_t = 320)]
    pub width: u32,
    #[arg(long, default_value_t = 240)]
    pub height: u32,
    /// Change the environment: `--set render.eye=[1.2,-0.8,1.3]`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
}

/// What one frame's overlay says.
struct Caption {
    episode: u32,
    step: u32,
    episode_return: f32,
    success: bool,
}

pub fn run(args: &RecordArgs) -> Result<()> {
    anyhow::ensure!(args.episodes > 0, "--episodes must be at least 1");
    let mp4 = match args.out.extension().and_then(|e| e.to_str()) {
        Some("gif") => false,
        Some("mp4") => {
            // No well-kept pure-Rust H.264 encoder exists; ffmpeg is the field's encoder.
            if std::process::Command::new("ffmpeg")
                .arg("-version")
                .output()
                .is_err()
            {
                bail!(
                    "{}: MP4 needs ffmpeg on the PATH, and there is none (install ffmpeg, or \
                     write a .gif)",
                    args.out.display()
                );
            }
            true
        }
        _ => bail!("{}: --out must end in .gif or .mp4", args.out.display()),
    };
    check_frame_size(args.width, args.height)?;
    let mut overrides = vec![
        "task.render_mode=rgb_array".to_string(),
        format!("render.width={}", args.width),
        format!("render.height={}", args.height),
    ];
    overrides.extend(args.overrides.iter().cloned());
    let (mut policy, id, table) =
        policy_and_env(args.id.as_deref(), args.model.as_deref(), &overrides)?;
    let mut env = RescaleAction::new(registry::make(&id, &table)?)?;
    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
    let mut frames: Vec<Vec<u8>> = Vec::new();
    let (w, h) = (args.width, args.height);
    let mut successes = 0;
    for e in 0..args.episodes {
        let (mut obs, _) = env.reset(Some(args.seed + e as u64))?;
        let mut caption = Caption {
            episode: e + 1,
            step: 0,
            episode_return: 0.0,
            success: false,
        };
        loop {
            frames.push(captioned(render_rgb(&mut env, w, h)?, w, h, &caption)?);
            let mut action = match policy.as_mut() {
                Some(p) => p.act_with_images(&obs, env.image(), true)?,
                None => (0..env.action_space().dim())
                    .map(|_| rng.random_range(-1.0f32..=1.0))
                    .collect(),
            };
            env.action_space().clip(&mut action);
            let step = env.step(&action)?;
            caption.step += 1;
            caption.episode_return += step.reward;
            caption.success |= step.info.success;
            obs = step.obs;
            if step.terminated || step.truncated {
                // The last state, held for half a second so the outcome can be read.
                let last = captioned(render_rgb(&mut env, w, h)?, w, h, &caption)?;
                frames.extend(std::iter::repeat_n(last, 15));
                successes += caption.success as u32;
                break;
            }
        }
    }
    let fps = env.metadata().render_fps;
    if mp4 {
        encode_mp4(&frames, w, h, fps, &args.out)?;
    } else {
        let bytes = fairgrasp_env::render::video::encode_gif(&frames, w, h, fps)?;
        fairgrasp_env::atomic::write(&args.out, &bytes)
            .with_context(|| format!("cannot write {}", args.out.display()))?;
    }
    println!(
        "wrote {} ({} frames, {w}×{h}): {} episode(s) of {id}, {successes} successful, {}",
        args.out.display(),
        frames.len(),
        args.episodes,
        match &args.model {
            Some(m) => format!("model {}", m.display()),
            None => "random actions".into(),
        }
    );
    Ok(())
}

fn render_rgb(env: &mut impl Env, w: u32, h: u32) -> Result<Vec<u8>> {
    match env.render()? {
        Some(Frame::Rgb {
            width,
            height,
            data,
        }) if width == w && height == h => Ok(data),
        Some(other) => bail!("expected a {w}×{h} RGB frame, got {other:?}"),
        None => bail!("the environment rendered nothing (rgb_array unsupported?)"),
    }
}

/// Draws the caption into the frame's top-left corner (plotters' text, the embedded font the
/// plots use).
fn captioned(mut rgb: Vec<u8>, w: u32, h: u32, c: &Caption) -> Result<Vec<u8>> {
    crate::plot_cmd::register_fonts();
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        let size = (h as f64 / 16.0).clamp(9.0, 24.0);
        let line = |text: String, row: i32, color: RGBColor| -> Result<()> {
            let style = ("sans-serif", size).into_font().color(&color);
            root.draw(&Text::new(text, (4, 2 + row * (size as i32 + 2)), style))
                .map_err(|e| anyhow::anyhow!("cannot draw the overlay: {e}"))
        };
        line(
            format!("episode {}  step {}", c.episode, c.step),
            0,
            RGBColor(20, 20, 20),
        )?;
        line(
            format!("return {:.2}", c.episode_return),
            1,
            RGBColor(20, 20, 20),
        )?;
        if c.success {
            line("success".into(), 2, RGBColor(0, 190, 0))?;
        }
        root.present()
            .map_err(|e| anyhow::anyhow!("cannot draw the overlay: {e}"))?;
    }
    Ok(rgb)
}

/// H.264 in MP4 through ffmpeg, raw RGB frames on its stdin; written next to `out` and renamed
/// into place, so a failed encode leaves no partial file.
fn encode_mp4(frames: &[Vec<u8>], w: u32, h: u32, fps: f32, out: &std::path::Path) -> Result<()> {
    use std::io::Write;
    use std::process::{Command, Stdio};
    let tmp = out.with_extension("partial.mp4");
    let mut child = Command::new("ffmpeg")
        .args([
            "-y",
            "-loglevel",
            "error",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "rgb24",
        ])
        .args([
            "-s",
            &format!("{w}x{h}"),
            "-r",
            &format!("{fps}"),
            "-i",
            "-",
        ])
        // yuv420p needs even sizes; players expect it.
        .args([
            "-vf",
            "pad=ceil(iw/2)*2:ceil(ih/2)*2",
            "-pix_fmt",
            "yuv420p",
        ])
        .arg(&tmp)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .context("cannot start ffmpeg")?;
    {
        let mut stdin = child.stdin.take().context("ffmpeg's stdin")?;
        for frame in frames {
            if stdin.write_all(frame).is_err() {
                break; // ffmpeg stopped reading: its error is reported below.
            }
        }
    }
    let result = child.wait_with_output().context("ffmpeg did not finish")?;
    if !result.status.success() {
        let _ = std::fs::remove_file(&tmp);
        bail!(
            "ffmpeg failed to write {}: {}",
            out.display(),
            String::from_utf8_lossy(&result.stderr).trim()
        );
    }
    std::fs::rename(&tmp, out).with_context(|| format!("cannot write {}", out.display()))
}
