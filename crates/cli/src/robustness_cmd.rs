//! `fairgrasp robustness`: a saved model's success over a grid of held-out conditions (object
//! mass and friction, action latency, observation noise, joint offsets), as a table and JSON.

use anyhow::Result;
use fairgrasp_deploy::robustness::{Grid, RobustnessOptions, evaluate_model};
use fairgrasp_rl::train::HELD_OUT_SEED_BASE;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct RobustnessArgs {
    /// Model directory (`runs/NAME/best`, …) or a run directory (its best model).
    #[arg(long)]
    pub model: PathBuf,
    /// Episodes per condition.
    #[arg(long, default_value_t = 100)]
    pub episodes: u32,
    /// First episode seed of every condition; episode k uses seed + k. The default range is
    /// used neither by training nor by its evaluations.
    #[arg(long, default_value_t = HELD_OUT_SEED_BASE)]
    pub seed: u64,
    /// Conditions evaluated at once.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Also write the results as JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// No progress lines.
    #[arg(long)]
    pub quiet: bool,
}

pub fn run(args: &RobustnessArgs) -> Result<()> {
    anyhow::ensure!(args.episodes > 0, "--episodes must be at least 1");
    anyhow::ensure!(args.threads > 0, "--threads must be at least 1");
    let options = RobustnessOptions {
        episodes: args.episodes,
        seed: args.seed,
        threads: args.threads,
    };
    let quiet = args.quiet;
    let report = evaluate_model(&args.model, &Grid::standard(), &options, &|done, total| {
        if !quiet {
            eprintln!("condition {done}/{total} done");
        }
    })?;
    print!("{}", report.table());
    println!("({:.0} s)", report.seconds);
    if let Some(out) = &args.out {
        report.save(out)?;
        println!("wrote {}", out.display());
    }
    Ok(())
}
