//! `fairgrasp env …`: list, check, exercise and measure the registered environments.

use anyhow::{Context, Result};
use fairgrasp_env::arm::{ArmEnv, Task};
use fairgrasp_env::check::{CheckReport, CheckVariant, check_env, variants as check_variants};
use fairgrasp_env::config::from_table;
use fairgrasp_env::config::{apply_override, read_table};
use fairgrasp_env::scripted::ScriptedGraspPolicy;
use fairgrasp_env::sim::rapier3d::na::{Isometry3, Point3, Vector3};
use fairgrasp_env::tasks::grasp::GraspConfig;
use fairgrasp_env::tasks::pick_place::PickPlaceEnv;
use fairgrasp_env::tasks::sort::SortEnv;
use fairgrasp_env::{Env, EpisodeEvent, GraspEnv, Info, VecEnv, VectorEnv, registry};
use rand::SeedableRng;
use std::path::PathBuf;
use std::time::Instant;

/// Environment settings shared by the `env` commands.
#[derive(clap::Args, Clone, Debug)]
pub struct EnvArgs {
    /// The environment (`fairgrasp env list`).
    #[arg(long = "env", default_value = fairgrasp_env::ENV_ID)]
    pub id: String,
    /// TOML file with the environment's settings (arm tasks: scene.*, control, task, reward,
    /// randomization, shapes, render).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Override a setting: `--set control.action_mode=cartesian --set randomization.enabled=true`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
}

impl EnvArgs {
    /// The settings table: the file (if any) with the overrides applied, validated.
    pub fn table(&self) -> Result<toml::Table> {
        let mut table = match &self.config {
            Some(path) => read_table(path)?,
            None => toml::Table::new(),
        };
        for item in &self.overrides {
            apply_override(&mut table, item)?;
        }
        registry::validate(&self.id, &table)
            .with_context(|| format!("invalid settings for {}", self.id))?;
        Ok(table)
    }

    /// Builds the environment.
    pub fn make(&self) -> Result<Box<dyn Env>> {
        Ok(registry::make(&self.id, &self.table()?)?)
    }

    /// The grasp task's typed configuration (for the commands only it supports).
    pub fn grasp_config(&self) -> Result<GraspConfig> {
        anyhow::ensure!(
            self.id == fairgrasp_env::ENV_ID,
            "this command supports {} only, not {}",
            fairgrasp_env::ENV_ID,
            self.id
        );
        Ok(fairgrasp_env::config::from_table(self.table()?)?)
    }
}

#[derive(clap::Subcommand)]
pub enum EnvCommand {
    /// The registered environments.
    List,
    /// Verify the Gymnasium contract, determinism and a NaN-free random rollout, for every
    /// observation preset, action mode and reward type, with and without randomisation
    /// (24 variants).
    Check(CheckArgs),
    /// Random actions: throughput and episode statistics.
    Random(RandomArgs),
    /// A scripted policy driven through step() (grasp, pick and place, sorting): success rate.
    Scripted(ScriptedArgs),
    /// Print the effective configuration as TOML (the defaults, with --config/--set applied).
    Config(EnvArgs),
    /// Reset an episode and write what the `[render]` camera sees as PNG images.
    Render(RenderArgs),
}

#[derive(clap::Args)]
pub struct RenderArgs {
    /// The RGB image (PNG).
    #[arg(long, default_value = "scene.png")]
    pub out: PathBuf,
    /// Also write the depth image here (grey: near is light, far and background black).
    #[arg(long)]
    pub depth: Option<PathBuf>,
    /// Episode seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[command(flatten)]
    pub env: EnvArgs,
}

#[derive(clap::Args)]
pub struct CheckArgs {
    /// Random-action steps per variant.
    #[arg(long, default_value_t = 10_000)]
    pub steps: u64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Check only the configuration as given, not every variant.
    #[arg(long)]
    pub only: bool,
    #[command(flatten)]
    pub env: EnvArgs,
}

#[derive(clap::Args)]
pub struct RandomArgs {
    /// Total environment steps (over all environments).
    #[arg(long, default_value_t = 10_000)]
    pub steps: u64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Environments stepped together (a vectorised env when above 1).
    #[arg(long, default_value_t = 1)]
    pub num_envs: usize,
    /// Worker threads of the vectorised env.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    #[command(flatten)]
    pub env: EnvArgs,
}

#[derive(clap::Args)]
pub struct ScriptedArgs {
    #[arg(long, default_value_t = 100)]
    pub episodes: u32,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[command(flatten)]
    pub env: EnvArgs,
}

pub fn run(command: EnvCommand) -> Result<()> {
    match command {
        EnvCommand::Check(args) => check(&args),
        EnvCommand::Random(args) => random(&args),
        EnvCommand::Scripted(args) => scripted(&args),
        EnvCommand::Render(args) => render(&args),
        EnvCommand::Config(args) => {
            let table = registry::effective_config(&args.id, &args.table()?)?;
            print!("{}", toml::to_string(&table)?);
            Ok(())
        }
        EnvCommand::List => {
            for spec in registry::specs() {
                println!("{:<20} {}", spec.id, spec.summary);
            }
            Ok(())
        }
    }
}

fn print_report(label: &str, report: &CheckReport) {
    let verdict = if report.passed() { "PASS" } else { "FAIL" };
    let e = &report.episodes;
    println!(
        "{verdict}  {label}: {} steps, episodes: {} success, {} time limit, {} off table, {} other; {} NaN observations",
        report.rollout_steps,
        e.success,
        e.time_limit,
        e.object_off_table,
        e.other,
        report.nan_observations
    );
    for (name, result) in &report.checks {
        if let Err(problem) = result {
            println!("      {name}: {problem}");
        }
    }
}

fn check(args: &CheckArgs) -> Result<()> {
    let base = args.env.table()?;
    let variants = if args.only {
        vec![CheckVariant {
            label: "as configured".into(),
            overrides: Vec::new(),
        }]
    } else {
        check_variants(&args.env.id)
    };
    let started = Instant::now();
    let mut failures = 0;
    for CheckVariant { label, overrides } in &variants {
        let mut table = base.clone();
        for item in overrides {
            apply_override(&mut table, item)?;
        }
        let mut env = registry::make(&args.env.id, &table)?;
        let mut twin = registry::make(&args.env.id, &table)?;
        let report = check_env(&mut env, &mut twin, args.steps, args.seed);
        print_report(label, &report);
        if !report.passed() {
            failures += 1;
        }
    }
    println!(
        "{} of {} variants passed in {:.1} s",
        variants.len() - failures,
        variants.len(),
        started.elapsed().as_secs_f64()
    );
    anyhow::ensure!(failures == 0, "{failures} variant(s) failed the check");
    Ok(())
}

fn random(args: &RandomArgs) -> Result<()> {
    anyhow::ensure!(args.num_envs >= 1, "--num-envs must be at least 1");
    let make = || args.env.make();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let mut stats = RolloutStats::default();
    let started = Instant::now();
    if args.num_envs == 1 {
        let mut env = make()?;
        env.reset(Some(args.seed))?;
        let mut episode_return = 0.0f64;
        for _ in 0..args.steps {
            let action = env.action_space().sample(&mut rng);
            let step = match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                env.step(&action)
            })) {
                Ok(step) => step.context("step failed")?,
                Err(_) => {
                    stats.panics += 1;
                    env.reset(None)?;
                    continue;
                }
            };
            stats.steps += 1;
            if step.obs.iter().any(|v| !v.is_finite()) {
                stats.nan_observations += 1;
            }
            episode_return += step.reward as f64;
            if step.terminated || step.truncated {
                stats.end_episode(&step.info, step.truncated, episode_return);
                episode_return = 0.0;
                env.reset(None)?;
            }
        }
    } else {
        let envs = (0..args.num_envs)
            .map(|_| make())
            .collect::<Result<Vec<_>>>()?;
        let mut venv = VecEnv::new(envs, args.threads)?;
        venv.reset(Some(args.seed))?;
        let n = venv.num_envs();
        let space = venv.action_space().clone();
        let mut actions = Vec::with_capacity(n * space.dim());
        while stats.steps < args.steps {
            actions.clear();
            for _ in 0..n {
                actions.extend(space.sample(&mut rng));
            }
            match venv.step(&actions) {
                Ok(step) => {
                    stats.steps += n as u64;
                    stats.nan_observations += step
                        .observations
                        .chunks(step.obs_dim)
                        .filter(|row| row.iter().any(|v| !v.is_finite()))
                        .count() as u64;
                    for (i, end) in step.episode_ends.iter().enumerate() {
                        if let Some(end) = end {
                            stats.end_episode(
                                &step.infos[i],
                                step.truncated[i],
                                end.episode.episode_return,
                            );
                        }
                    }
                }
                Err(e) => {
                    // An environment failed or panicked; the others stepped. Count and recover.
                    stats.panics += 1;
                    eprintln!("warning: {e}");
                    venv.reset(None)?;
                }
            }
        }
    }
    let elapsed = started.elapsed().as_secs_f64();
    println!(
        "{} random steps of {} in {elapsed:.1} s: {:.0} env steps/s, {} env(s), {} thread(s)",
        stats.steps,
        args.env.id,
        stats.steps as f64 / elapsed,
        args.num_envs,
        if args.num_envs == 1 { 1 } else { args.threads }
    );
    stats.print();
    anyhow::ensure!(
        stats.nan_observations == 0 && stats.panics == 0 && stats.other == 0,
        "the rollout had NaN observations, panics or unexplained episode ends"
    );
    Ok(())
}

/// Episode statistics of a rollout.
#[derive(Default)]
struct RolloutStats {
    steps: u64,
    episodes: u64,
    returns: f64,
    lengths: u64,
    success: u64,
    time_limit: u64,
    off_table: u64,
    other: u64,
    nan_observations: u64,
    panics: u64,
}

impl RolloutStats {
    fn end_episode(&mut self, info: &Info, truncated: bool, episode_return: f64) {
        self.episodes += 1;
        self.returns += episode_return;
        self.lengths += info.elapsed_steps as u64;
        if info.success {
            self.success += 1;
        } else if info.events.contains(&EpisodeEvent::ObjectOffTable) {
            self.off_table += 1;
        } else if truncated && !info.events.contains(&EpisodeEvent::NonFiniteState) {
            self.time_limit += 1;
        } else {
            self.other += 1;
        }
    }

    fn print(&self) {
        let n = self.episodes.max(1) as f64;
        println!(
            "episodes: {} (success {}, time limit {}, object off table {}, other {}); mean return {:.3}, mean length {:.1}",
            self.episodes,
            self.success,
            self.time_limit,
            self.off_table,
            self.other,
            self.returns / n,
            self.lengths as f64 / n
        );
        println!(
            "NaN observations: {}, panics: {}",
            self.nan_observations, self.panics
        );
    }
}

/// One scripted episode of an arm task: `(success, steps)`. The plan picks the objects that
/// `objects(env)` lists after the reset, in turn, carrying each to `goal(env, i)` when there is
/// one and releasing it there if `release`.
fn scripted_episode<T: Task>(
    env: &mut ArmEnv<T>,
    seed: u64,
    goal: impl Fn(&ArmEnv<T>, usize) -> Option<Vector3<f64>>,
    objects: impl Fn(&ArmEnv<T>) -> Vec<usize>,
    release: bool,
) -> Result<(bool, u32)> {
    env.reset(Some(seed))?;
    for i in objects(env) {
        let mut policy = ScriptedGraspPolicy::for_object(env, i, goal(env, i), release);
        while !policy.done() {
            let step = env.step(&policy.act(env))?;
            if step.terminated || step.truncated {
                return Ok((step.info.success, step.info.elapsed_steps));
            }
        }
    }
    // Every object placed without the success rule holding: wait out the episode.
    loop {
        let mut hold = vec![0.0; env.action_space().dim()];
        *hold.last_mut().expect("a gripper entry") = 1.0;
        let step = env.step(&hold)?;
        if step.terminated || step.truncated {
            return Ok((step.info.success, step.info.elapsed_steps));
        }
    }
}

fn scripted(args: &ScriptedArgs) -> Result<()> {
    anyhow::ensure!(args.episodes > 0, "--episodes must be at least 1");
    let table = args.env.table()?;
    let mode = table
        .get("control")
        .and_then(|c| c.get("action_mode"))
        .and_then(|m| m.as_str())
        .unwrap_or("joint")
        .to_string();
    let world_goal =
        |base: Isometry3<f64>, local: Vector3<f64>| (base * Point3::from(local)).coords;
    let mut run: Box<dyn FnMut(u64) -> Result<(bool, u32)>> = match args.env.id.as_str() {
        "FaArmGrasp-v0" => {
            let mut env = GraspEnv::new(from_table(table)?)?;
            Box::new(move |seed| scripted_episode(&mut env, seed, |_, _| None, |_| vec![0], false))
        }
        "FaArmPickPlace-v0" => {
            let mut env = PickPlaceEnv::new(from_table(table)?)?;
            Box::new(move |seed| {
                let goal =
                    |e: &PickPlaceEnv, _| Some(world_goal(e.scene().base_pose(), e.task().goal()));
                scripted_episode(&mut env, seed, goal, |_| vec![0], false)
            })
        }
        "FaArmSort-v0" => {
            let mut env = SortEnv::new(from_table(table)?)?;
            Box::new(move |seed| {
                let goal = |e: &SortEnv, i| {
                    Some(world_goal(e.scene().base_pose(), e.task().drop_point(i)))
                };
                let objects = |e: &SortEnv| e.task().objects_to_sort();
                scripted_episode(&mut env, seed, goal, objects, true)
            })
        }
        other => anyhow::bail!("no scripted policy for {other}; it has the arm tasks only"),
    };
    let started = Instant::now();
    let mut successes = 0;
    let mut lengths = 0u64;
    let mut failed = Vec::new();
    for i in 0..args.episodes as u64 {
        let seed = args.seed + i;
        let (success, steps) = run(seed)?;
        if success {
            successes += 1;
            lengths += steps as u64;
        } else {
            failed.push(seed);
        }
    }
    println!(
        "scripted policy through step(), {} in {mode} mode: {successes}/{} successes ({:.1}%), mean length of successful episodes {:.1} steps, {:.1} s",
        args.env.id,
        args.episodes,
        100.0 * successes as f64 / args.episodes as f64,
        lengths as f64 / successes.max(1) as f64,
        started.elapsed().as_secs_f64()
    );
    if !failed.is_empty() {
        println!("failed seeds: {failed:?}");
    }
    Ok(())
}

/// One frame of a fresh episode in `mode`, from an environment built with `env` and the mode set.
fn render_frame(env: &EnvArgs, mode: &str, seed: u64) -> Result<fairgrasp_env::core::Frame> {
    let mut args = env.clone();
    args.overrides.push(format!("task.render_mode={mode}"));
    let mut env = args.make()?;
    env.reset(Some(seed))?;
    env.render()?
        .with_context(|| format!("{} has no {mode} render mode", args.id))
}

fn render(args: &RenderArgs) -> Result<()> {
    use fairgrasp_env::core::Frame;
    use fairgrasp_env::render::image::{depth_to_rgb, write_png};
    match render_frame(&args.env, "rgb_array", args.seed)? {
        Frame::Rgb {
            width,
            height,
            data,
        } => {
            write_png(&args.out, width, height, &data)?;
            println!("wrote {} ({width}×{height})", args.out.display());
        }
        other => anyhow::bail!("expected an RGB frame, got {other:?}"),
    }
    if let Some(path) = &args.depth {
        match render_frame(&args.env, "depth_array", args.seed)? {
            Frame::Depth {
                width,
                height,
                data,
            } => {
                let far = data.iter().copied().fold(0.0f32, f32::max);
                let near = data.iter().copied().fold(far, f32::min);
                // Stretch the range the scene occupies, not near..far of the camera.
                let scene_far = data
                    .iter()
                    .copied()
                    .filter(|&d| d < far)
                    .fold(near, f32::max);
                write_png(path, width, height, &depth_to_rgb(&data, near, scene_far))?;
                println!("wrote {} ({width}×{height})", path.display());
            }
            other => anyhow::bail!("expected a depth frame, got {other:?}"),
        }
    }
    Ok(())
}
