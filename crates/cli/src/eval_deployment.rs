//! `fairgrasp eval --deployment`: the deployment-matched evaluation. The model runs through the
//! deployment's own loop (state estimation, safety filter, servo schedule, success rule) against
//! the twin's controller model and world in this process, on a simulated clock with drawn reply
//! latencies: what `fairgrasp deploy` on `fairgrasp twin` measures, without sockets or real
//! time, so it is fast and independent of the host's load.

use anyhow::{Context, Result};
use fairgrasp_deploy::calibration::Calibration;
use fairgrasp_deploy::runner::{AfterSuccess, DeployOptions, ModelIo};
use fairgrasp_deploy::safety::SafetyConfig;
use fairgrasp_deploy::twin::evaluation::{Evaluation, evaluate};
use fairgrasp_deploy::twin::faults::FaultCommand;
use fairgrasp_deploy::twin::simulated::{SimulatedController, SimulatedSettings};
use fairgrasp_rl::Policy;
use fairgrasp_rl::train::wilson_lower_bound;

#[derive(clap::Args)]
pub struct DeploymentEvalArgs {
    /// Run the model through the deployment loop against the simulated controller (see
    /// docs/deployment.md) instead of the training env.
    #[arg(long)]
    pub deployment: bool,
    /// With --deployment: the speed scale, as `fairgrasp deploy --speed-scale`.
    #[arg(long, default_value_t = 0.25, requires = "deployment")]
    pub speed_scale: f64,
    /// With --deployment: each call's reply latency (ms), drawn from latency ± jitter.
    #[arg(long, default_value_t = 10.0, requires = "deployment")]
    pub latency_ms: f64,
    #[arg(long, default_value_t = 5.0, requires = "deployment")]
    pub latency_jitter_ms: f64,
    /// With --deployment: encoder noise on the streamed joints (deg).
    #[arg(long, default_value_t = 0.05, requires = "deployment")]
    pub joint_noise_deg: f64,
    /// With --deployment, for a camera policy: how long after its capture a frame reaches the
    /// loop (ms; the camera takes one every 33 ms).
    #[arg(long, default_value_t = 40.0, requires = "deployment")]
    pub camera_delay_ms: f64,
    /// With --deployment: the controller as `fairgrasp twin --strict` sets it, as far as a
    /// simulated clock models it: drives 8 ms behind their set points with a 15 ms lag, and
    /// collision detection at 150 N (the network's faults are the real-time twin's).
    #[arg(long, requires = "deployment")]
    pub strict: bool,
    /// With --deployment: write the deployment loop's log (`fairgrasp deploy --log`: every
    /// state, command and policy step) to this file; the loop restarted after a fault writes
    /// to the next free `FILE.2.jsonl`, …, its episodes counted from 0 again.
    #[arg(long, value_name = "FILE.jsonl", requires = "deployment")]
    pub log: Option<std::path::PathBuf>,
}

/// What `fairgrasp eval` names besides the deployment's own options.
pub struct Run<'a> {
    /// The model directory.
    pub model: &'a std::path::Path,
    /// Episodes to play.
    pub episodes: u32,
    /// The first episode's seed.
    pub seed: u64,
    /// Print the result as JSON.
    pub json: bool,
}

pub fn run(args: &Run<'_>, d: &DeploymentEvalArgs) -> Result<()> {
    let policy = Policy::load(args.model)
        .with_context(|| format!("cannot load model {}", args.model.display()))?;
    let io = ModelIo::for_policy(&policy)?;
    let calibration = Calibration::identity(&io.limits_rad);
    let (low, high) = settings_range(d);
    let settings = SimulatedSettings {
        latency_ms: [low, high],
        joint_noise_deg: d.joint_noise_deg,
        camera_delay_ms: d.camera_delay_ms,
        seed: args.seed,
        ..SimulatedSettings::default()
    };
    let table = fairgrasp_rl::model::env_table(policy.env_config())?;
    let link = SimulatedController::new(policy.env_id(), &table, settings)?;
    if d.strict {
        for fault in fairgrasp_deploy::twin::faults::strict() {
            match fault {
                FaultCommand::Tracking(model) => link.set_tracking(model),
                FaultCommand::CollisionLevelN(level) => link.set_collision_level(level),
                _ => {}
            }
        }
    }
    let started = std::time::Instant::now();
    let options = DeployOptions {
        live: true,
        episodes: args.episodes,
        safety: SafetyConfig {
            speed_scale: d.speed_scale,
            ..SafetyConfig::default()
        },
        // Judged at success; putting the object down would only add simulated time.
        after_success: AfterSuccess::Hold,
        ..DeployOptions::default()
    };
    let evaluation = evaluate(
        &link,
        args.model,
        &calibration,
        &options,
        args.seed,
        d.log.as_deref(),
    )?;
    for why in &evaluation.mismatches {
        eprintln!("warning: {why}");
    }
    for (i, fault) in evaluation.faults.iter().enumerate() {
        println!("fault {}: {fault}", i + 1);
    }
    let Evaluation {
        played,
        successes,
        faults,
        ..
    } = evaluation;
    let seconds = started.elapsed().as_secs_f64();
    let rate = successes as f64 / played.max(1) as f64;
    let bound = wilson_lower_bound(successes, played);
    if args.json {
        println!(
            "{}",
            serde_json::json!({
                "model": args.model.display().to_string(),
                "deployment": true,
                "speed_scale": d.speed_scale,
                "latency_ms": [low, high],
                "joint_noise_deg": d.joint_noise_deg,
                "strict": d.strict,
                "episodes": played,
                "seed": args.seed,
                "successes": successes,
                "success_rate": rate,
                "wilson_lower_bound": bound,
                "faults": faults,
                "simulated_seconds": link.elapsed(),
                "seconds": seconds,
            })
        );
    } else {
        println!(
            "{} through the deployment loop on the simulated controller{} (speed scale {}, \
             latency {low:.0}-{high:.0} ms, encoder noise {} deg), {played} episodes from seed {}:",
            args.model.display(),
            if d.strict { ", strict" } else { "" },
            d.speed_scale,
            d.joint_noise_deg,
            args.seed
        );
        println!(
            "  success rate {:.1}% ({successes} of {played}), 95% lower bound {:.1}%",
            rate * 100.0,
            bound * 100.0
        );
        println!(
            "  {:.0} s of controller time in {seconds:.1} s",
            link.elapsed()
        );
        if !faults.is_empty() {
            println!(
                "  {} episode(s) stopped by a fault, counted as failed: {}",
                faults.len(),
                faults.join("; ")
            );
        }
    }
    Ok(())
}

fn settings_range(d: &DeploymentEvalArgs) -> (f64, f64) {
    (
        (d.latency_ms - d.latency_jitter_ms).max(0.0),
        d.latency_ms + d.latency_jitter_ms,
    )
}
