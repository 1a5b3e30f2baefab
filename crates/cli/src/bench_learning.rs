//! `fairgrasp bench learning`: the learning benchmark. Trains each algorithm with its default
//! configuration (each in a child process, so the peak memory is that run's), evaluates the best
//! model on held-out episodes, and writes success rate against environment steps and against
//! wall time (a table and an SVG plot) into docs/benchmarks.md.
//!
//! The figures are generated, never typed: the section between the `learning` markers of the
//! output file is rewritten, the rest of the file is kept.

use anyhow::{Context, Result, bail};
use fairgrasp_rl::Algo;
use fairgrasp_rl::Policy;
use fairgrasp_rl::logger::ProgressLog;
use fairgrasp_rl::train::{EvalResult, HELD_OUT_SEED_BASE, TrainSummary};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct LearningBenchArgs {
    /// Algorithms to train, in order [default: ppo and sac].
    #[arg(long = "algo", value_parser = crate::train_cmd::algo_parser())]
    pub algos: Vec<Algo>,
    /// Summarise a finished run instead of training: `--run ppo=runs/ppo_grasp`.
    #[arg(long = "run", value_name = "ALGO=RUN_DIR")]
    pub runs: Vec<String>,
    /// Wall-clock budget of each training run (minutes).
    #[arg(long, default_value_t = 30.0)]
    pub minutes: f64,
    /// Held-out evaluation episodes of each best model.
    #[arg(long, default_value_t = 100)]
    pub episodes: u32,
    /// Where the training runs go.
    #[arg(long, default_value = "runs/bench")]
    pub runs_dir: PathBuf,
    /// Markdown file whose learning section is rewritten (created if missing).
    #[arg(long, default_value = "docs/benchmarks.md")]
    pub out: PathBuf,
    /// Environment every run trains on, with its own built-in configuration (as `fairgrasp
    /// train --env`), e.g. FaArmPickPlace-v0 [default: the grasp task].
    #[arg(long)]
    pub env: Option<String>,
    /// Override a training setting of every run (as `fairgrasp train --set`).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
}

/// One point of the evaluation curve logged during training.
#[derive(Clone, Copy, Debug)]
struct CurvePoint {
    steps: f64,
    seconds: f64,
    success: f64,
}

struct RunResult {
    algo: String,
    env_id: String,
    seed: u64,
    /// Physics steps per simulated second, for the arm tasks.
    physics: Option<String>,
    dir: PathBuf,
    summary: TrainSummary,
    curve: Vec<CurvePoint>,
    held_out: EvalResult,
}

pub fn run(args: &LearningBenchArgs) -> Result<()> {
    let mut jobs: Vec<(String, Option<PathBuf>)> = Vec::new();
    for item in &args.runs {
        let (algo, dir) = item
            .split_once('=')
            .with_context(|| format!("--run {item}: expected ALGO=RUN_DIR"))?;
        jobs.push((algo.to_string(), Some(PathBuf::from(dir))));
    }
    let algos = if args.algos.is_empty() && jobs.is_empty() {
        vec![Algo::Ppo, Algo::Sac]
    } else {
        args.algos.clone()
    };
    jobs.extend(algos.into_iter().map(|a| (a.as_str().to_string(), None)));
    let mut results = Vec::new();
    for (algo, dir) in jobs {
        let dir = match dir {
            Some(dir) => dir,
            None => train_child(&algo, args)?,
        };
        results.push(summarise(&algo, &dir, args.episodes)?);
    }
    let plot = args.out.with_file_name("img").join("learning_curves.svg");
    draw_curves(&results, &plot)?;
    let section = markdown(&results, args, &plot);
    write_section(&args.out, &section)?;
    println!("{section}");
    println!("wrote {} and {}", args.out.display(), plot.display());
    Ok(())
}

/// Trains `algo` with its default configuration in a child process; returns the run directory.
fn train_child(algo: &str, args: &LearningBenchArgs) -> Result<PathBuf> {
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let dir = args.runs_dir.join(format!("{algo}_{stamp}"));
    let exe = std::env::current_exe().context("cannot find the fairgrasp executable")?;
    let mut command = std::process::Command::new(exe);
    command.args(["train", "--algo", algo, "--quiet", "--run-dir"]);
    command.arg(&dir);
    command.args(["--set", &format!("max_seconds={}", args.minutes * 60.0)]);
    if let Some(env) = &args.env {
        command.args(["--env", env]);
    }
    for item in &args.overrides {
        command.args(["--set", item]);
    }
    println!(
        "training {algo} for at most {} min into {}",
        args.minutes,
        dir.display()
    );
    let status = command.status().context("cannot start training")?;
    if !status.success() {
        bail!("training {algo} failed ({status})");
    }
    Ok(dir)
}

fn summarise(algo: &str, dir: &Path, episodes: u32) -> Result<RunResult> {
    let path = dir.join("summary.json");
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("{}: not a finished run", path.display()))?;
    let summary: TrainSummary =
        serde_json::from_str(&text).with_context(|| format!("{}", path.display()))?;
    let curve = eval_curve(&dir.join("progress.csv"))?;
    let best = dir.join("best");
    let policy = Policy::load(&best)?;
    let env = crate::eval_cmd::model_env(&policy, &[])?;
    let held_out =
        crate::eval_cmd::evaluate_model(&policy, &best, &env, episodes, HELD_OUT_SEED_BASE, 0)?;
    Ok(RunResult {
        algo: algo.to_string(),
        env_id: policy.env_id().to_string(),
        seed: policy.meta().train_seed,
        physics: physics_label(&policy.meta().env, policy.env_id()),
        dir: dir.to_path_buf(),
        summary,
        curve,
        held_out,
    })
}

/// The physics of a model's arm task: its `scene.physics.dt` as a rate (else the scene's default;
/// models store only the settings their training changed), and "kinematic" when its arm used the
/// kinematic drive. `None` for tasks without the arm.
fn physics_label(env: &serde_json::Value, env_id: &str) -> Option<String> {
    if !env_id.starts_with("FaArm") {
        return None;
    }
    let dt = env
        .pointer("/scene/physics/dt")
        .and_then(|v| v.as_f64())
        .unwrap_or(fairgrasp_sim::scene::PhysicsConfig::default().dt as f64);
    let kinematic = env.pointer("/scene/arm/drive").and_then(|v| v.as_str()) == Some("kinematic");
    (dt > 0.0).then(|| {
        let hz = format!("{:.0} Hz", 1.0 / dt);
        if kinematic {
            format!("{hz}, kinematic arm")
        } else {
            hz
        }
    })
}

/// The rows of progress.csv that hold an evaluation.
fn eval_curve(path: &Path) -> Result<Vec<CurvePoint>> {
    let log = ProgressLog::read(path)?;
    let columns = [
        "time/total_timesteps",
        "time/time_elapsed",
        "eval/success_rate",
    ];
    if columns.iter().any(|c| log.column(c).is_none()) {
        bail!("{}: no evaluation columns", path.display());
    }
    let [steps, seconds, success] = columns.map(|c| log.values(c));
    Ok(steps
        .zip(seconds)
        .zip(success)
        .filter_map(|((steps, seconds), success)| {
            Some(CurvePoint {
                steps: steps?,
                seconds: seconds?,
                success: success?,
            })
        })
        .collect())
}

/// The first evaluation at or above `threshold`.
fn first_reaching(curve: &[CurvePoint], threshold: f64) -> Option<CurvePoint> {
    curve
        .iter()
        .copied()
        .find(|p| p.success >= threshold - 1e-9)
}

fn markdown(results: &[RunResult], args: &LearningBenchArgs, plot: &Path) -> String {
    let mut s = String::new();
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    let cpu = crate::host::cpu_model();
    let _ = writeln!(s, "## Learning: success rate against steps and wall time\n");
    let command: Vec<String> = std::env::args().skip(1).collect();
    let _ = writeln!(
        s,
        "Generated by `fairgrasp {}` on {cpu} ({cores} cores available). Each algorithm trains \
         with its default configuration for its task (configs/<algo>_grasp.toml, \
         configs/ppo_pick_place.toml) within \
         its wall-clock budget (`--minutes`, {} here for runs trained by this command; a run \
         given with `--run` had its own budget and may have had its own configuration: the \
         physics column gives each run's rate and names the kinematic arm drive where it was \
         used), stopping early once 49 of 50 evaluation episodes succeed. The curve is the evaluation during training (deterministic policy, 50 episodes, \
         seeds 1,000,000…); the last columns evaluate the best model on {} held-out episodes \
         (seeds 2,000,000,000…), as `fairgrasp eval` does.\n",
        command.join(" "),
        args.minutes,
        args.episodes
    );
    let _ = writeln!(
        s,
        "| algorithm | task | seed | physics | steps trained | wall time | env steps/s (updates included) | peak memory | 90 % reached at | 95 % reached at | held-out success | held-out mean return |"
    );
    let _ = writeln!(
        s,
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    for r in results {
        let at = |t: f64| {
            first_reaching(&r.curve, t)
                .map(|p| format!("{:.0}k steps, {}", p.steps / 1e3, wall_time(p.seconds)))
                .unwrap_or_else(|| "not reached".into())
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.0}k | {} | {:.0} | {} | {} | {} | {:.0} % ({} episodes) | {:.2} |",
            r.algo.to_uppercase(),
            r.env_id,
            r.seed,
            r.physics.as_deref().unwrap_or("—"),
            r.summary.num_timesteps as f64 / 1e3,
            wall_time(r.summary.seconds),
            r.summary.fps,
            r.summary
                .peak_memory_mib
                .map(|m| format!("{m:.0} MiB"))
                .unwrap_or_else(|| "n/a".into()),
            at(0.9),
            at(0.95),
            r.held_out.success_rate * 100.0,
            r.held_out.episodes,
            r.held_out.mean_return,
        );
    }
    let _ = writeln!(
        s,
        "\n![success rate against steps and wall time](img/{})\n",
        plot.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    );
    for r in results {
        let _ = writeln!(
            s,
            "<details><summary>{} on {} (seed {}) evaluation curve ({})</summary>\n",
            r.algo.to_uppercase(),
            r.env_id,
            r.seed,
            r.dir.display()
        );
        let _ = writeln!(s, "| env steps | wall time (min) | eval success |");
        let _ = writeln!(s, "|---:|---:|---:|");
        for p in &r.curve {
            let _ = writeln!(
                s,
                "| {:.0} | {:.1} | {:.0} % |",
                p.steps,
                p.seconds / 60.0,
                p.success * 100.0
            );
        }
        let _ = writeln!(s, "\n</details>\n");
    }
    s
}

const BEGIN: &str = "<!-- learning:begin (generated by `fairgrasp bench learning`) -->";
const END: &str = "<!-- learning:end -->";

/// Replaces the learning section of `path` (or appends it), writing atomically.
fn write_section(path: &Path, section: &str) -> Result<()> {
    let old = std::fs::read_to_string(path).unwrap_or_else(|_| "# Benchmarks\n\n".into());
    let block = format!("{BEGIN}\n{section}{END}\n");
    let text = match (old.find(BEGIN), old.find(END)) {
        (Some(b), Some(e)) if e > b => format!("{}{block}{}", &old[..b], &old[e + END.len()..]),
        _ => format!("{}\n\n{block}", old.trim_end()),
    };
    fairgrasp_env::atomic::write(path, text.as_bytes())
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Seconds under two minutes (the default PPO's runs), minutes above.
fn wall_time(seconds: f64) -> String {
    if seconds < 120.0 {
        format!("{seconds:.0} s")
    } else {
        format!("{:.1} min", seconds / 60.0)
    }
}

/// `FaArmPickPlace-v0` → `PickPlace`: the task in a legend.
fn short_task(env_id: &str) -> &str {
    let stem = env_id.split("-v").next().unwrap_or(env_id);
    stem.strip_prefix("FaArm").unwrap_or(stem)
}

/// Success rate against steps (left) and wall time (right), one line per run.
fn draw_curves(results: &[RunResult], path: &Path) -> Result<()> {
    use plotters::prelude::*;
    crate::plot_cmd::register_fonts();
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let root = SVGBackend::new(path, (1000, 380)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e}"))?;
    let panels = root.split_evenly((1, 2));
    let max_steps = results
        .iter()
        .flat_map(|r| r.curve.iter().map(|p| p.steps))
        .fold(1.0, f64::max);
    let max_minutes = results
        .iter()
        .flat_map(|r| r.curve.iter().map(|p| p.seconds / 60.0))
        .fold(1.0, f64::max);
    let colours = [BLUE, RED, GREEN, MAGENTA];
    for (panel, by_time) in panels.iter().zip([false, true]) {
        let (x_max, x_label) = if by_time {
            (max_minutes, "wall time (min)")
        } else {
            (max_steps / 1e6, "environment steps (millions)")
        };
        let mut chart = ChartBuilder::on(panel)
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(44)
            .build_cartesian_2d(0.0..x_max, 0.0..100.0)
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc("eval success (%)")
            .draw()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        for (r, colour) in results.iter().zip(colours.iter().cycle()) {
            let points = r.curve.iter().map(|p| {
                let x = if by_time {
                    p.seconds / 60.0
                } else {
                    p.steps / 1e6
                };
                (x, p.success * 100.0)
            });
            chart
                .draw_series(LineSeries::new(points, colour.stroke_width(2)))
                .map_err(|e| anyhow::anyhow!("{e}"))?
                .label(format!(
                    "{} {} s{}",
                    r.algo.to_uppercase(),
                    short_task(&r.env_id),
                    r.seed
                ))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .draw()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
    }
    root.present().map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn physics_is_the_models_rate_and_drive_or_the_scenes_default() {
        let label = |env: serde_json::Value, id: &str| physics_label(&env, id);
        let at_120 = serde_json::json!({ "scene": { "physics": { "dt": 1.0 / 120.0 } } });
        assert_eq!(label(at_120, "FaArmGrasp-v0").as_deref(), Some("120 Hz"));
        assert_eq!(
            label(serde_json::json!({}), "FaArmPickPlace-v0").as_deref(),
            Some("240 Hz")
        );
        let kinematic = serde_json::json!({ "scene": { "arm": { "drive": "kinematic" } } });
        assert_eq!(
            label(kinematic, "FaArmGrasp-v0").as_deref(),
            Some("240 Hz, kinematic arm")
        );
        assert_eq!(label(serde_json::json!({}), "Pendulum-v1"), None);
        assert_eq!(short_task("FaArmPickPlace-v0"), "PickPlace");
        assert_eq!(short_task("Pendulum-v1"), "Pendulum");
        assert_eq!(wall_time(37.1), "37 s");
        assert_eq!(wall_time(301.0), "5.0 min");
    }
}
