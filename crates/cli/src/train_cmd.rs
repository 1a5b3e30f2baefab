//! `fairgrasp train`: PPO, SAC or TD3 on any registered environment with evaluation, best-model
//! saving, checkpoints and resume, TensorBoard and CSV logs, and a progress bar.

use anyhow::{Context, Result, bail};
use fairgrasp_rl::Algo;
use fairgrasp_rl::configs::builtin_table;
use fairgrasp_rl::ppo::pixel::PixelIteration;
use fairgrasp_rl::train::RunDir;
use fairgrasp_rl::train::pixel::run_pixel_ppo;
use fairgrasp_rl::train::{Progress, TrainConfig, TrainSummary, resume_until, train_until};
use indicatif::{ProgressBar, ProgressStyle};
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// `--algo`: the names of [`Algo::ALL`], listed in the help and completed by the shell.
pub fn algo_parser() -> impl clap::builder::TypedValueParser<Value = Algo> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(Algo::ALL.map(Algo::as_str))
        .try_map(|name| name.parse::<Algo>())
}

#[derive(clap::Args)]
pub struct TrainArgs {
    /// Training configuration (TOML; every key: configs/ppo_grasp.toml, configs/sac_grasp.toml,
    /// configs/td3_grasp.toml).
    /// Without it, the built-in default of the algorithm.
    #[arg(long, conflicts_with = "resume")]
    pub config: Option<PathBuf>,
    /// Algorithm (overrides the config's `algo`).
    #[arg(long, value_parser = algo_parser(), conflicts_with = "resume")]
    pub algo: Option<Algo>,
    /// The environment to learn (`fairgrasp env list`), overriding the config's `env_id`
    /// [default: FaArmGrasp-v0].
    #[arg(long, conflicts_with = "resume")]
    pub env: Option<String>,
    #[arg(long)]
    pub total_timesteps: Option<u64>,
    #[arg(long, conflicts_with = "resume")]
    pub seed: Option<u64>,
    /// Where logs, checkpoints and models go [default: runs/<algo>_grasp, or the next free
    /// runs/<algo>_grasp_<n>].
    #[arg(long, conflicts_with = "resume")]
    pub run_dir: Option<PathBuf>,
    /// Continue the run in this directory from its latest checkpoint.
    #[arg(long, value_name = "RUN_DIR")]
    pub resume: Option<PathBuf>,
    /// Override a setting: `--set ppo.learning_rate=1e-4 --set env.task.max_episode_steps=80`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
    /// Train through the arm's drives as `fairgrasp sysid` identified them: each joint's delay
    /// and lag from the file become `[env.control.drives]` (needs `[env.control.servo]`; set
    /// `env.control.drives.scale` to randomise around them).
    #[arg(long, value_name = "SYSID.toml", conflicts_with = "resume")]
    pub drives: Option<PathBuf>,
    /// No progress bar (for logs); one line per evaluation instead.
    #[arg(long)]
    pub quiet: bool,
}

/// The settings that train through the drives in a `fairgrasp sysid` file, and the env id they
/// were fitted against.
fn drive_overrides(path: &std::path::Path) -> Result<(Vec<String>, String)> {
    let model = fairgrasp_deploy::sysid::DriveModel::load(path)?;
    let tracking = model.tracking();
    let list = |f: fn(&fairgrasp_deploy::twin::faults::JointTracking) -> f64| {
        let values: Vec<String> = tracking.iter().map(|t| format!("{:?}", f(t))).collect();
        format!("[{}]", values.join(", "))
    };
    let overrides = vec![
        "env.control.drives.enabled=true".to_string(),
        format!("env.control.drives.delay_ms={}", list(|t| t.delay_ms)),
        format!("env.control.drives.tau_ms={}", list(|t| t.tau_ms)),
    ];
    Ok((overrides, model.env))
}

pub fn run(args: &TrainArgs) -> Result<()> {
    let mut overrides = args.overrides.clone();
    if let Some(n) = args.total_timesteps {
        overrides.push(format!("total_timesteps={n}"));
    }
    if let Some(dir) = &args.resume {
        let mut reporter = Reporter::new(args.quiet);
        let stop = stop_on_ctrl_c()?;
        let summary = resume_until(dir, &overrides, |p| reporter.update_until(p, &stop))
            .with_context(|| format!("resuming {}", dir.display()))?;
        reporter.finish();
        return print_summary(&summary);
    }
    if let Some(s) = args.seed {
        overrides.push(format!("seed={s}"));
    }
    if let Some(algo) = args.algo {
        overrides.push(format!("algo=\"{algo}\""));
    }
    if let Some(env) = &args.env {
        fairgrasp_env::registry::spec(env)?;
        overrides.push(format!("env_id=\"{env}\""));
    }
    let fitted_on = match &args.drives {
        Some(path) => {
            let (more, env) = drive_overrides(path)?;
            println!("drives from {}: {}", path.display(), more[1..].join(", "));
            overrides.extend(more);
            Some(env)
        }
        None => None,
    };
    let (text, origin) = match &args.config {
        Some(path) => (
            std::fs::read_to_string(path)
                .with_context(|| format!("cannot read {}", path.display()))?,
            format!("invalid config {}", path.display()),
        ),
        None => {
            let env_id = args.env.as_deref().unwrap_or(fairgrasp_env::ENV_ID);
            let table = builtin_table(env_id, args.algo.unwrap_or_default())?;
            (table.to_string(), "invalid settings".into())
        }
    };
    let config = TrainConfig::from_toml_str(&text, &overrides).context(origin)?;
    if let Some(env) = fitted_on
        && env != config.env_id
    {
        bail!(
            "--drives: the file's drives were fitted against {env}'s simulated arm, not {}'s",
            config.env_id
        );
    }
    let run_dir = match &args.run_dir {
        Some(dir) => {
            if RunDir::new(dir).holds_a_run() {
                bail!(
                    "{} already holds a training run; continue it with --resume {0}, or choose another --run-dir",
                    dir.display()
                );
            }
            dir.clone()
        }
        None => RunDir::default_for(config.algo.algo().as_str(), &config.env_id)
            .path()
            .to_path_buf(),
    };
    println!(
        "training {} on {} for {} steps ({} envs, seed {}) into {}",
        config.algo.algo().as_str(),
        config.env_id,
        config.total_timesteps,
        config.n_envs,
        config.seed,
        run_dir.display()
    );
    let stop = stop_on_ctrl_c()?;
    if config.pixel_ppo.is_some() {
        return train_pixel(&config, &run_dir, args.quiet, &stop);
    }
    let mut reporter = Reporter::new(args.quiet);
    let summary = train_until(&config, &run_dir, |p| reporter.update_until(p, &stop))?;
    reporter.finish();
    print_summary(&summary)?;
    if let Some(distill) = &config.distill {
        if stop.load(Ordering::SeqCst) {
            println!("interrupted: no camera policy distilled");
            return Ok(());
        }
        let run = RunDir::new(&run_dir);
        // The best model when an evaluation chose one, else the final one.
        let teacher = Some(run.best_model())
            .filter(|p| p.join("model.json").exists())
            .unwrap_or_else(|| run.final_model());
        crate::distill_cmd::distill_and_report(
            &teacher,
            &run_dir.join("student"),
            distill,
            config.seed,
        )
        .map(|_| ())?;
    }
    Ok(())
}

/// `[pixel_ppo]`: the camera policy trained end to end, a line per iteration, then its
/// held-out success.
fn train_pixel(
    config: &TrainConfig,
    run_dir: &std::path::Path,
    quiet: bool,
    stop: &AtomicBool,
) -> Result<()> {
    let mut on_iteration = |it: &PixelIteration| {
        if !quiet {
            println!(
                "{:>9} steps: {}/{} rollout episodes succeeded, {:.0} % grasped, return {:.2}, std {:.3}, value loss {:.4}, KL {:.4} (env {:.1} s, act {:.1} s, update {:.1} s)",
                it.timesteps,
                it.successes,
                it.episodes,
                100.0 * it.grasped,
                it.mean_return,
                it.std,
                it.value_loss,
                it.approx_kl,
                it.env_seconds,
                it.act_seconds,
                it.update_seconds
            );
        }
        match stop.load(Ordering::SeqCst) {
            true => ControlFlow::Break(()),
            false => ControlFlow::Continue(()),
        }
    };
    let (summary, _) = run_pixel_ppo(config, run_dir, &mut on_iteration)
        .with_context(|| format!("training a camera policy into {}", run_dir.display()))?;
    println!(
        "camera policy: {}/{} held-out episodes succeeded after {} steps in {:.0} s (env steps {:.0} s, acting {:.0} s, update {:.0} s of which the actor's forward {:.0} s, backward and Adam {:.0} s; peak memory {}); model in {}",
        summary.successes,
        summary.episodes,
        summary.num_timesteps,
        summary.seconds,
        summary.env_seconds,
        summary.act_seconds,
        summary.update_seconds,
        summary.forward_seconds,
        summary.backward_seconds,
        summary
            .peak_memory_mib
            .map_or("unknown".into(), |m| format!("{m:.0} MiB")),
        RunDir::new(run_dir).final_model().display()
    );
    Ok(())
}

/// Ctrl-C (SIGINT) asks the run to stop after its current iteration, writing its final model,
/// logs and summary as at its end (the latest checkpoint stays for `--resume`); a second Ctrl-C
/// quits at once. Installed over an ignored SIGINT too (a shell's background job).
fn stop_on_ctrl_c() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::SeqCst) {
            eprintln!("\ninterrupted again: quitting without the final model");
            std::process::exit(130);
        }
        eprintln!("\ninterrupted: stopping after this iteration (Ctrl-C again to quit at once)");
    })
    .context("cannot install the Ctrl-C handler")?;
    Ok(stop)
}

/// Progress bar (or, quietly, one line per evaluation).
struct Reporter {
    bar: Option<ProgressBar>,
    evaluations: usize,
    started: std::time::Instant,
}

impl Reporter {
    fn new(quiet: bool) -> Self {
        // The bar's length comes with the first progress report (the run's total steps).
        let bar = (!quiet).then(|| {
            let bar = ProgressBar::new(0);
            bar.set_style(
                ProgressStyle::with_template(
                    "{elapsed_precise} [{bar:30}] {pos}/{len} steps, ETA {eta} {msg}",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
            bar
        });
        Self {
            bar,
            evaluations: 0,
            started: std::time::Instant::now(),
        }
    }

    /// [`Self::update`], then whether the run goes on (not once `stop` is set).
    fn update_until(&mut self, p: &Progress, stop: &AtomicBool) -> ControlFlow<()> {
        self.update(p);
        if stop.load(Ordering::SeqCst) {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }

    fn update(&mut self, p: &Progress) {
        let mut msg = format!("{:.0} fps", p.fps);
        if let Some(r) = p.ep_rew_mean {
            msg.push_str(&format!(", ep_rew_mean {r:.2}"));
        }
        if let Some(g) = p.rollout_max_extras.get("grasped") {
            msg.push_str(&format!(", grasp {:.0}%", g * 100.0));
        }
        if let Some(s) = p.rollout_success_rate {
            msg.push_str(&format!(", success {:.0}%", s * 100.0));
        }
        if let Some(e) = &p.last_eval {
            msg.push_str(&format!(", eval success {:.0}%", e.success_rate * 100.0));
        }
        match &self.bar {
            Some(bar) => {
                bar.set_length(p.total_timesteps);
                bar.set_position(p.num_timesteps.min(p.total_timesteps));
                bar.set_message(msg);
            }
            None => {
                if self.evaluations < p.eval_count {
                    self.evaluations = p.eval_count;
                    let seconds = self.started.elapsed().as_secs();
                    println!("{seconds:>5} s, {} steps: {msg}", p.num_timesteps);
                }
            }
        }
    }

    fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish();
        }
    }
}

fn print_summary(summary: &TrainSummary) -> Result<()> {
    if let Some(step) = summary.resumed_from {
        println!("resumed from step {step}");
    }
    println!(
        "trained {} steps in {:.0} s ({:.0} steps/s); run directory {}",
        summary.num_timesteps,
        summary.seconds,
        summary.fps,
        summary.run_dir.display()
    );
    if summary.reached_threshold {
        println!("stopped early: the evaluation success threshold was reached");
    }
    if summary.stopped {
        println!("stopped early by Ctrl-C; the final model is in the run directory");
    }
    if let Some(mib) = summary.peak_memory_mib {
        println!("peak memory {mib:.0} MiB");
    }
    if let Some(best) = &summary.best {
        let over = if best.confirmed {
            format!(" over {} validation episodes", best.episodes)
        } else {
            String::new()
        };
        println!(
            "best evaluation: success {:.1}%{over}, mean return {:.2}, mean length {:.1} (model in {})",
            best.success_rate * 100.0,
            best.mean_return,
            best.mean_length,
            summary.run_dir.join("best").display()
        );
    }
    Ok(())
}
