//! `fairgrasp train`: PPO on the grasp task with evaluation, best-model saving, checkpoints,
//! TensorBoard and CSV logs, and a progress bar.

use anyhow::{Context, Result};
use fairgrasp_rl::train::{TrainConfig, train_ppo};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct TrainArgs {
    /// Training configuration (TOML): total_timesteps, seed, n_envs, ppo.*, env.*, eval.*.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Algorithm (ppo; sac comes with the training issue's second half).
    #[arg(long, default_value = "ppo")]
    pub algo: String,
    #[arg(long)]
    pub total_timesteps: Option<u64>,
    #[arg(long)]
    pub seed: Option<u64>,
    /// Where logs, checkpoints and models go.
    #[arg(long, default_value = "runs/ppo_grasp")]
    pub run_dir: PathBuf,
    /// Override a setting: `--set ppo.learning_rate=1e-4 --set env.task.max_episode_steps=80`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
}

pub fn run(args: &TrainArgs) -> Result<()> {
    anyhow::ensure!(
        args.algo == "ppo",
        "--algo {} is not available yet; use ppo",
        args.algo
    );
    let text = match &args.config {
        Some(path) => std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?,
        None => String::new(),
    };
    let mut overrides = args.overrides.clone();
    if let Some(n) = args.total_timesteps {
        overrides.push(format!("total_timesteps={n}"));
    }
    if let Some(s) = args.seed {
        overrides.push(format!("seed={s}"));
    }
    let config = TrainConfig::from_toml_str(&text, &overrides).with_context(|| {
        args.config
            .as_ref()
            .map(|p| format!("invalid config {}", p.display()))
            .unwrap_or_else(|| "invalid settings".into())
    })?;
    let bar = ProgressBar::new(config.total_timesteps);
    bar.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] {pos}/{len} steps, ETA {eta} {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    let summary = train_ppo(&config, &args.run_dir, |p| {
        bar.set_position(p.num_timesteps.min(p.total_timesteps));
        let mut msg = format!("{:.0} fps", p.fps);
        if let Some(r) = p.ep_rew_mean {
            msg.push_str(&format!(", ep_rew_mean {r:.2}"));
        }
        if let Some(s) = p.rollout_success_rate {
            msg.push_str(&format!(", success {:.0}%", s * 100.0));
        }
        if let Some(e) = &p.last_eval {
            msg.push_str(&format!(", eval success {:.0}%", e.success_rate * 100.0));
        }
        bar.set_message(msg);
    })?;
    bar.finish();
    println!(
        "trained {} steps in {:.0} s; run directory {}",
        summary.num_timesteps,
        summary.seconds,
        summary.run_dir.display()
    );
    if let Some(best) = summary.best {
        println!(
            "best evaluation: success {:.0}%, mean return {:.2}, mean length {:.1}",
            best.success_rate * 100.0,
            best.mean_return,
            best.mean_length
        );
    }
    Ok(())
}
