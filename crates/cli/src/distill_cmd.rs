//! `fairgrasp distill`: teach a camera policy from a trained state policy (DAgger), then
//! evaluate it alone on held-out episodes; also the last stage of `fairgrasp train` when its
//! config has `[distill]`.

use anyhow::{Context, Result};
use fairgrasp_env::wrappers::RescaleAction;
use fairgrasp_env::{Env, registry};
use fairgrasp_rl::Policy;
use fairgrasp_rl::distill::stage::run_stage;
use fairgrasp_rl::distill::{DistillConfig, RoundReport, evaluate_student};
use fairgrasp_rl::policies::pixel_actor::PixelActor;
use fairgrasp_rl::train::HELD_OUT_SEED_BASE;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct DistillArgs {
    /// The teacher: a model directory or run directory of a state policy.
    #[arg(long)]
    pub teacher: PathBuf,
    /// Where the student's weights and summary go.
    #[arg(long, default_value = "runs/distill")]
    pub run_dir: PathBuf,
    /// Change a distillation setting (`[distill]` keys): `--set rounds=12`,
    /// `--set env.camera.randomize.enabled=true`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Also evaluate the student under visual conditions outside its training ranges
    /// (dimmer, brighter and lower light, other colours, a camera moved more, more noise).
    #[arg(long)]
    pub held_out: bool,
}

/// Visual conditions the student never saw in training (`camera.randomize` moved outside the
/// default ranges), each with the randomisation otherwise as in training.
pub const HELD_OUT_CONDITIONS: &[(&str, &[&str])] = &[
    (
        "dim light (brightness 0.55-0.65)",
        &["camera.randomize.brightness=[0.55, 0.65]"],
    ),
    (
        "bright light (1.35-1.45)",
        &["camera.randomize.brightness=[1.35, 1.45]"],
    ),
    (
        "low light (elevation 15-25°)",
        &["camera.randomize.light_elevation_deg=[15.0, 25.0]"],
    ),
    (
        "pale colours (tint 1.25-1.35)",
        &["camera.randomize.tint=[1.25, 1.35]"],
    ),
    (
        "dark colours (tint 0.65-0.75)",
        &["camera.randomize.tint=[0.65, 0.75]"],
    ),
    (
        "camera moved more (3 cm, 4.5°, fov ±4.5°)",
        &[
            "camera.randomize.position_jitter=0.03",
            "camera.randomize.angle_jitter_deg=4.5",
            "camera.randomize.fov_jitter_deg=4.5",
        ],
    ),
    (
        "twice the pixel noise (6 levels)",
        &["camera.randomize.pixel_noise=6.0"],
    ),
];

/// Runs the distillation stage, printing each round and the student's held-out success;
/// returns the student as saved.
pub fn distill_and_report(
    teacher: &Path,
    student_dir: &Path,
    config: &DistillConfig,
    seed: u64,
) -> Result<Policy> {
    println!(
        "distilling {} into a camera policy: {} envs, {} rounds of {} steps (CPU: {})",
        teacher.display(),
        config.n_envs,
        config.rounds,
        config.steps_per_round,
        crate::host::cpu_model()
    );
    let mut on_round = |r: &RoundReport, _: &PixelActor| {
        println!(
            "round {:>2}: β {:.2}, {:>6} states, loss {:.4}, {}/{} episodes succeeded, collect {:.1} s, train {:.1} s",
            r.round,
            r.beta,
            r.samples,
            r.loss,
            r.successes,
            r.episodes,
            r.collect_seconds,
            r.train_seconds
        );
        ControlFlow::Continue(())
    };
    let (summary, student) = run_stage(teacher, student_dir, config, seed, &mut on_round)
        .with_context(|| format!("distilling {}", teacher.display()))?;
    println!(
        "student: {}/{} held-out episodes succeeded; {} parameters, {} labelled states; distilled in {:.0} s (env steps {:.0} s, acting {:.0} s, student forward {:.0} s, backward and Adam {:.0} s; peak memory {}) into {}",
        summary.successes,
        summary.episodes,
        summary.parameters,
        summary.samples,
        summary.distill_seconds,
        summary.env_seconds,
        summary.act_seconds,
        summary.forward_seconds,
        summary.backward_seconds,
        summary
            .peak_memory_mib
            .map_or("unknown".into(), |m| format!("{m:.0} MiB")),
        student_dir.display()
    );
    Ok(student)
}

pub fn run(args: &DistillArgs) -> Result<()> {
    let config: DistillConfig = fairgrasp_env::config::parse_toml("", &args.overrides)
        .context("the distillation settings")?;
    let mut student = distill_and_report(&args.teacher, &args.run_dir, &config, args.seed)?;
    if args.held_out {
        evaluate_held_out(&config, &mut student)?;
    }
    Ok(())
}

/// The saved student under each of [`HELD_OUT_CONDITIONS`].
fn evaluate_held_out(config: &DistillConfig, student: &mut Policy) -> Result<()> {
    let base = student.env_settings(&[])?;
    let env_id = student.env_id().to_string();
    for (name, overrides) in HELD_OUT_CONDITIONS {
        let mut table = base.clone();
        fairgrasp_env::config::apply_override(&mut table, "camera.randomize.enabled=true")?;
        for o in overrides.iter() {
            fairgrasp_env::config::apply_override(&mut table, o)?;
        }
        let mut env = RescaleAction::new(registry::make(&env_id, &table)?)?;
        let successes =
            evaluate_student(student, &mut env, config.eval_episodes, HELD_OUT_SEED_BASE)?;
        env.close();
        println!("  {name}: {successes}/{}", config.eval_episodes);
    }
    Ok(())
}
