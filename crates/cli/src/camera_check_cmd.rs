//! `fairgrasp camera-check`: reads a camera feed as the deployment would (docs/deployment.md,
//! "Camera feed") for a few seconds and reports, per camera, the frames received, their rate
//! and age, and the picture's mean colour: the feed's commissioning before a camera policy runs.

use anyhow::{Context, Result, bail};
use fairgrasp_deploy::frame_source::{FrameSource, TcpFrames};
use fairgrasp_rl::Policy;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct CameraCheckArgs {
    /// The camera policy (its model.json names the images it reads).
    #[arg(long)]
    pub model: PathBuf,
    /// The camera feed's address (the twin's: 127.0.0.1:20101).
    #[arg(long, value_name = "IP:PORT")]
    pub camera_tcp: String,
    /// How long to read.
    #[arg(long, default_value_t = 3.0)]
    pub seconds: f64,
}

pub fn run(args: &CameraCheckArgs) -> Result<()> {
    anyhow::ensure!(
        args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= 600.0,
        "--seconds must be in (0, 600]"
    );
    let policy = Policy::load(&args.model)
        .with_context(|| format!("cannot load model {}", args.model.display()))?;
    let Some(space) = policy.image_space() else {
        bail!("{} reads no camera images", args.model.display());
    };
    let mut feed = TcpFrames::connect(
        &args.camera_tcp,
        space,
        Duration::from_secs(2),
        Duration::from_secs(2),
    )
    .with_context(|| format!("the camera feed at {}", args.camera_tcp))?;
    let first = feed.wait_first(Duration::from_secs(5))?;
    let started = Instant::now();
    let mut last_stamps = first.stamps.clone();
    let mut frames = vec![1u32; space.views.len()];
    let (mut age_sum, mut age_max, mut samples) = (0.0f64, 0.0f64, 0u32);
    let mut newest = first;
    while started.elapsed().as_secs_f64() < args.seconds {
        std::thread::sleep(Duration::from_millis(5));
        let Some(images) = feed.latest()? else {
            continue;
        };
        for (v, stamp) in images.stamps.iter().enumerate() {
            if *stamp != last_stamps[v] {
                frames[v] += 1;
                last_stamps[v] = *stamp;
            }
        }
        let age = images.received_at.elapsed().as_secs_f64() * 1000.0;
        (age_sum, age_max, samples) = (age_sum + age, age_max.max(age), samples + 1);
        newest = images;
    }
    let seconds = started.elapsed().as_secs_f64();
    println!("camera feed {}: {}", args.camera_tcp, space.describe());
    for (v, view) in space.views.iter().enumerate() {
        let pixels = &newest.bytes[space.range(v)];
        let channels = view.channels as usize;
        let mean: Vec<String> = (0..channels)
            .map(|c| {
                let sum: u64 = pixels
                    .iter()
                    .skip(c)
                    .step_by(channels)
                    .map(|&p| p as u64)
                    .sum();
                format!("{:.0}", sum as f64 / (pixels.len() / channels) as f64)
            })
            .collect();
        println!(
            "  {}: {} frames in {seconds:.1} s ({:.1} per second), mean value per channel [{}]",
            view.name,
            frames[v],
            frames[v] as f64 / seconds,
            mean.join(", ")
        );
    }
    let deadline = fairgrasp_deploy::safety::SafetyConfig::default().frame_deadline_ms;
    println!(
        "  age on arrival of the newest frames: mean {:.0} ms, max {:.0} ms (the deployment's \
         deadline: {deadline:.0} ms)",
        age_sum / samples.max(1) as f64,
        age_max
    );
    Ok(())
}
