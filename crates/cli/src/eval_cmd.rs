//! `fairgrasp eval`: a saved model's deterministic success rate, mean return and episode length
//! on held-out episodes.

use anyhow::{Context, Result};
use fairgrasp_rl::Policy;
use fairgrasp_rl::train::{
    Actor, EVAL_SEED_BASE, EvalResult, HELD_OUT_SEED_BASE, evaluate, evaluate_parallel,
};
use std::io::Write;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct EvalArgs {
    /// Model directory (`runs/NAME/best`, `runs/NAME/final`, a checkpoint) or a run directory
    /// (its best model).
    #[arg(long)]
    pub model: PathBuf,
    #[arg(long, default_value_t = 100)]
    pub episodes: u32,
    /// First episode seed; episode k uses seed + k. The default range is used neither by
    /// training nor by the evaluations that chose the best model.
    #[arg(long, default_value_t = HELD_OUT_SEED_BASE)]
    pub seed: u64,
    /// Change the environment the model is evaluated in, e.g. `--set randomization.enabled=true`
    /// (by default: the environment it was trained on).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Threads playing the episodes (0: one per CPU); the result does not depend on it.
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Write every observation the policy saw and the action it chose, one JSON object per
    /// line (`{"obs": [...], "action": [...]}`), to this file: for comparing other runtimes
    /// (the Python package, an ONNX export) with this one.
    #[arg(long, value_name = "FILE.jsonl")]
    pub trace: Option<PathBuf>,
    #[command(flatten)]
    pub deployment: crate::eval_deployment::DeploymentEvalArgs,
}

pub fn run(args: &EvalArgs) -> Result<()> {
    anyhow::ensure!(args.episodes > 0, "--episodes must be at least 1");
    if args.deployment.deployment {
        anyhow::ensure!(
            args.overrides.is_empty() && args.trace.is_none(),
            "--set and --trace do not apply to --deployment (the model's own settings are deployed)"
        );
        let run = crate::eval_deployment::Run {
            model: &args.model,
            episodes: args.episodes,
            seed: args.seed,
            json: args.json,
        };
        return crate::eval_deployment::run(&run, &args.deployment);
    }
    let mut policy = Policy::load(&args.model)
        .with_context(|| format!("cannot load model {}", args.model.display()))?;
    let env = model_env(&policy, &args.overrides)?;
    let seeds = args.seed..args.seed.saturating_add(args.episodes as u64);
    let meta = policy.meta();
    let train_seeds = meta.train_seed..meta.train_seed + meta.n_envs.max(1) as u64;
    let overlaps = |r: &std::ops::Range<u64>| seeds.start < r.end && r.start < seeds.end;
    if overlaps(&train_seeds) || overlaps(&(EVAL_SEED_BASE..EVAL_SEED_BASE + 10_000)) {
        eprintln!(
            "warning: seeds {}..{} overlap those of training ({}..{}) or of its evaluations ({}..): the result is not held-out",
            seeds.start, seeds.end, train_seeds.start, train_seeds.end, EVAL_SEED_BASE
        );
    }
    let started = std::time::Instant::now();
    let env_id = policy.env_id().to_string();
    let mut trace = match &args.trace {
        Some(path) => Some(std::io::BufWriter::new(
            std::fs::File::create(path)
                .with_context(|| format!("cannot create {}", path.display()))?,
        )),
        None => None,
    };
    let result = match &mut trace {
        // One thread: the trace lists the steps in order.
        Some(out) => evaluate(
            &mut |obs, images| {
                let action = policy.act_with_images(obs, images, true)?;
                let line = serde_json::json!({ "obs": obs, "action": action });
                writeln!(out, "{line}").map_err(|e| {
                    fairgrasp_rl::error::RlError::Other(format!("writing the trace: {e}"))
                })?;
                Ok(action)
            },
            &env_id,
            &env,
            args.episodes,
            args.seed,
        )?,
        None => evaluate_model(
            &policy,
            &args.model,
            &env,
            args.episodes,
            args.seed,
            args.threads,
        )?,
    };
    if let Some(mut out) = trace {
        out.flush().context("writing the trace")?;
    }
    let seconds = started.elapsed().as_secs_f64();
    let dir = policy.dir().unwrap_or(&args.model).display().to_string();
    let meta = policy.meta();
    if args.json {
        println!(
            "{{\"model\": {:?}, \"env_id\": {:?}, \"algo\": {:?}, \"trained_steps\": {}, \"episodes\": {}, \"seed\": {}, \"success_rate\": {}, \"mean_return\": {}, \"mean_length\": {}, \"final_extras\": {}, \"seconds\": {seconds:.2}}}",
            dir,
            env_id,
            meta.algo.algo().as_str(),
            meta.num_timesteps,
            args.episodes,
            args.seed,
            result.success_rate,
            result.mean_return,
            result.mean_length,
            serde_json::to_string(&result.final_extras)?
        );
    } else {
        println!(
            "{} ({} on {}, trained {} steps), {} episodes from seed {}:",
            dir,
            meta.trained_by(),
            env_id,
            meta.num_timesteps,
            args.episodes,
            args.seed
        );
        println!(
            "  success rate {:.1}% ({} of {})",
            result.success_rate * 100.0,
            (result.success_rate * args.episodes as f32).round() as u32,
            args.episodes
        );
        println!("  mean return  {:.2}", result.mean_return);
        println!("  mean length  {:.1} steps", result.mean_length);
        for (name, value) in result.final_extras.iter() {
            println!("  {name:<12} {value:.3} (mean at the episode's end)");
        }
        println!("  ({seconds:.1} s)");
    }
    Ok(())
}

/// `policy`'s held-out evaluation on `env` (its settings table), the episodes shared out over
/// `threads` threads, each acting through its own copy of the model read from `path`.
pub fn evaluate_model(
    policy: &Policy,
    path: &std::path::Path,
    env: &toml::Table,
    episodes: u32,
    seed: u64,
    threads: usize,
) -> Result<EvalResult> {
    let dir = policy.dir().unwrap_or(path).to_path_buf();
    let make_actor = || -> fairgrasp_rl::error::Result<Actor<'static>> {
        let mut copy = Policy::load(&dir)?;
        Ok(Box::new(move |obs: &[f32], images: Option<&[u8]>| {
            copy.act_with_images(obs, images, true)
        }))
    };
    Ok(evaluate_parallel(
        &make_actor,
        policy.env_id(),
        env,
        episodes,
        seed,
        threads,
    )?)
}

/// The settings of the environment a model was trained on (rebuilt through the registry by
/// `evaluate`), with `overrides` applied and checked.
pub fn model_env(policy: &Policy, overrides: &[String]) -> Result<toml::Table> {
    Ok(policy.env_settings(overrides)?)
}

/// The policy (if a model is given), the env id (`id`, else the model's, else the grasp task)
/// and its settings table with `overrides` applied and checked: what `record` and `view` run.
pub fn policy_and_env(
    id: Option<&str>,
    model: Option<&std::path::Path>,
    overrides: &[String],
) -> Result<(Option<Policy>, String, toml::Table)> {
    let policy = match model {
        Some(path) => Some(
            Policy::load(path).with_context(|| format!("cannot load model {}", path.display()))?,
        ),
        None => None,
    };
    let id = match (id, &policy) {
        (Some(id), _) => id.to_string(),
        (None, Some(p)) => p.env_id().to_string(),
        (None, None) => fairgrasp_env::ENV_ID.to_string(),
    };
    let table = match &policy {
        Some(p) => {
            anyhow::ensure!(
                p.env_id() == id,
                "the model was trained on {}, not {id}",
                p.env_id()
            );
            model_env(p, overrides)?
        }
        None => {
            let mut table = toml::Table::new();
            for item in overrides {
                fairgrasp_env::config::apply_override(&mut table, item).context("invalid --set")?;
            }
            fairgrasp_env::registry::validate(&id, &table)
                .with_context(|| format!("invalid settings for {id}"))?;
            table
        }
    };
    Ok((policy, id, table))
}

/// Frame sizes `record` and `view` accept.
pub fn check_frame_size(width: u32, height: u32) -> Result<()> {
    anyhow::ensure!(
        (16..=1920).contains(&width) && (16..=1080).contains(&height),
        "--width and --height must be within 16×16 and 1920×1080, got {width}×{height}"
    );
    Ok(())
}
