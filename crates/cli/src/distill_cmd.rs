//! `fairgrasp distill`: teach a camera policy from a trained state policy (DAgger), then
//! evaluate it alone on held-out episodes.

use anyhow::{Context, Result};
use fairgrasp_env::wrappers::RescaleAction;
use fairgrasp_env::{Env, VecEnv, registry};
use fairgrasp_rl::Policy;
use fairgrasp_rl::algorithm::TensorMap;
use fairgrasp_rl::distill::{DistillConfig, RoundReport, distill, evaluate_student};
use fairgrasp_rl::model::save_tensors;
use fairgrasp_rl::train::HELD_OUT_SEED_BASE;
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Args)]
pub struct DistillArgs {
    /// The teacher: a model directory or run directory of a state policy.
    #[arg(long)]
    pub teacher: PathBuf,
    /// Where the student's weights go.
    #[arg(long, default_value = "runs/distill")]
    pub run_dir: PathBuf,
    /// Change the student's environment (the teacher's, with `camera.mode="rgb+state"`), e.g.
    /// `--env-set camera.width=96`.
    #[arg(long = "env-set", value_name = "KEY=VALUE")]
    pub env_overrides: Vec<String>,
    /// Change a distillation setting, e.g. `--set rounds=12` (`[distill]` keys).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
    #[arg(long, default_value_t = 16)]
    pub n_envs: usize,
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Held-out episodes the student plays alone at the end.
    #[arg(long, default_value_t = 100)]
    pub eval_episodes: u32,
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

pub fn run(args: &DistillArgs) -> Result<()> {
    let started = Instant::now();
    let mut teacher = Policy::load(&args.teacher)
        .with_context(|| format!("cannot load the teacher {}", args.teacher.display()))?;
    let mut env_overrides = vec!["camera.mode=\"rgb+state\"".to_string()];
    env_overrides.extend(args.env_overrides.iter().cloned());
    let table = teacher.env_settings(&env_overrides)?;
    let env_id = teacher.env_id().to_string();
    let config: DistillConfig = fairgrasp_env::config::parse_toml("", &args.overrides)
        .context("the distillation settings")?;
    let envs = (0..args.n_envs)
        .map(|_| Ok(RescaleAction::new(registry::make(&env_id, &table)?)?))
        .collect::<Result<Vec<_>>>()?;
    let mut envs = VecEnv::new(envs, args.threads)?;
    let teacher_dim = teacher.obs_dim();
    let mut label = |rows: &[f32]| teacher.act_batch(rows, true);
    let cpu = crate::host::cpu_model();
    println!(
        "distilling {} into a camera policy: {} envs, {} rounds of {} steps (CPU: {cpu})",
        args.teacher.display(),
        args.n_envs,
        config.rounds,
        config.steps_per_round
    );
    let mut on_round = |r: &RoundReport, _: &fairgrasp_rl::policies::pixel_actor::PixelActor| {
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
    let student = distill(
        &mut label,
        teacher_dim,
        &mut envs,
        &config,
        args.seed,
        &mut on_round,
    )?;
    let trained = started.elapsed().as_secs_f64();
    std::fs::create_dir_all(&args.run_dir)
        .with_context(|| format!("cannot create {}", args.run_dir.display()))?;
    let weights: TensorMap = {
        let data = student.varmap().data().lock().expect("varmap lock");
        data.iter()
            .map(|(k, v)| (k.clone(), v.as_tensor().clone()))
            .collect()
    };
    save_tensors(&args.run_dir.join("student.safetensors"), &weights)?;
    let mut eval_env = RescaleAction::new(registry::make(&env_id, &table)?)?;
    let successes = evaluate_student(
        &student,
        &mut eval_env,
        args.eval_episodes,
        HELD_OUT_SEED_BASE,
    )?;
    eval_env.close();
    println!(
        "student: {successes}/{} held-out episodes succeeded; {} parameters; trained in {trained:.0} s, {:.0} s in all",
        args.eval_episodes,
        student.parameter_count(),
        started.elapsed().as_secs_f64()
    );
    if args.held_out {
        for (name, overrides) in HELD_OUT_CONDITIONS {
            let mut settings = env_overrides.clone();
            settings.push("camera.randomize.enabled=true".into());
            settings.extend(overrides.iter().map(|o| o.to_string()));
            let table = teacher.env_settings(&settings)?;
            let mut env = RescaleAction::new(registry::make(&env_id, &table)?)?;
            let successes =
                evaluate_student(&student, &mut env, args.eval_episodes, HELD_OUT_SEED_BASE)?;
            println!("  {name}: {successes}/{}", args.eval_episodes);
        }
    }
    Ok(())
}
