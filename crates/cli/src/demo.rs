//! `fairgrasp demo …`: scripted demonstrations in simulation.

use crate::scene_args::SceneArgs;
use anyhow::Result;
use fairgrasp_env::tasks::grasp::GraspSettings;
use fairgrasp_sim::pick::{PickScript, evaluate_scripted_pick};
use fairgrasp_sim::scene::Scene;

#[derive(clap::Subcommand)]
pub enum DemoCommand {
    /// Pick up the cube with a scripted controller: above, align, descend, close, lift, hold.
    ScriptedPick(ScriptedPickArgs),
}

#[derive(clap::Args)]
pub struct ScriptedPickArgs {
    /// Number of episodes (each with its own random cube placement).
    #[arg(long, default_value_t = 100)]
    pub episodes: u32,
    /// Seed of the first episode; episode i uses seed + i.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print one line per episode.
    #[arg(long, short)]
    pub verbose: bool,
    #[command(flatten)]
    pub scene: SceneArgs,
}

pub fn run(command: DemoCommand) -> Result<()> {
    match command {
        DemoCommand::ScriptedPick(args) => scripted_pick(&args),
    }
}

fn scripted_pick(args: &ScriptedPickArgs) -> Result<()> {
    anyhow::ensure!(args.episodes > 0, "--episodes must be at least 1");
    let config = args.scene.scene_config()?;
    let mut scene = Scene::new(config)?;
    println!(
        "scripted pick: {} episodes from seed {}, physics {:.0} Hz, control {:.1} Hz ({} substeps)",
        args.episodes,
        args.seed,
        1.0 / scene.dt(),
        1.0 / scene.control_period(),
        scene.config().physics.substeps
    );
    let started = std::time::Instant::now();
    // The grasp task's own rule: the script is judged as a trained policy is.
    let rule = GraspSettings::default().success_rule();
    let report = evaluate_scripted_pick(
        &mut scene,
        args.episodes,
        args.seed,
        &PickScript::default(),
        rule,
        |seed, outcome| {
            if args.verbose {
                let result = match &outcome.failure {
                    None => "success".to_string(),
                    Some(failure) => format!("FAILED ({failure})"),
                };
                println!(
                    "  seed {seed:>5}: {result}, lift {:.3} m, hold drift {:.2} mm",
                    outcome.final_lift,
                    outcome.hold_drift * 1000.0
                );
            }
        },
    )?;
    let elapsed = started.elapsed().as_secs_f64();
    for (seed, failure) in &report.failures {
        println!("  seed {seed}: failed: {failure}");
    }
    println!(
        "success: {}/{} ({:.1}%)  [rule: closed on object, lifted > {:.0} cm, within {:.0} cm of the TCP, {} consecutive control steps]",
        report.successes,
        report.episodes,
        100.0 * report.successes as f64 / report.episodes as f64,
        rule.min_lift * 100.0,
        rule.max_offset * 100.0,
        rule.hold_steps
    );
    let counts = report.failure_counts();
    if !counts.is_empty() {
        println!("failures by reason:");
        for (kind, count) in counts {
            println!("  {count:>5}  {kind}");
        }
    }
    println!(
        "cube drift relative to the fingers during the 1 s hold: max {:.2} mm, mean {:.2} mm",
        report.max_drift * 1000.0,
        report.mean_drift * 1000.0
    );
    println!("wall time: {elapsed:.1} s");
    Ok(())
}
