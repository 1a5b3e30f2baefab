//! `fairgrasp bench …`: simulator throughput on one thread, printed as plain figures.
//!
//! The criterion benchmarks in `crates/sim/benches` measure the same loops with statistics; this
//! command is the quick, scriptable version (`--json` for machines).

use crate::SceneArgs;
use anyhow::Result;
use fairgrasp_sim::pick::{PickScript, grasp_and_lift};
use fairgrasp_sim::scene::Scene;
use std::time::Instant;

#[derive(clap::Subcommand)]
pub enum BenchCommand {
    /// Physics steps per second of the full scene and scene resets per second.
    Physics(PhysicsBenchArgs),
}

#[derive(clap::Args)]
pub struct PhysicsBenchArgs {
    /// Seconds of wall time per measurement.
    #[arg(long, default_value_t = 3.0)]
    pub seconds: f64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub scene: SceneArgs,
}

pub fn run(command: BenchCommand) -> Result<()> {
    match command {
        BenchCommand::Physics(args) => physics(&args),
    }
}

/// Runs `f` repeatedly for about `seconds`; returns calls per second.
fn rate(seconds: f64, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    // Warm up caches and allocations.
    for _ in 0..10 {
        f()?;
    }
    let start = Instant::now();
    let mut calls = 0u64;
    while start.elapsed().as_secs_f64() < seconds {
        for _ in 0..50 {
            f()?;
        }
        calls += 50;
    }
    Ok(calls as f64 / start.elapsed().as_secs_f64())
}

fn physics(args: &PhysicsBenchArgs) -> Result<()> {
    anyhow::ensure!(args.seconds > 0.0, "--seconds must be positive");
    let mut scene = Scene::new(args.scene.scene_config()?)?;

    // Arm holding its home pose, cube resting on the table.
    scene.reset(0)?;
    let idle = scene.snapshot();
    let mut n = 0u64;
    let idle_rate = rate(args.seconds, || {
        n += 1;
        if n.is_multiple_of(2400) {
            scene.restore(&idle);
        }
        scene.step_physics().map_err(Into::into)
    })?;

    // Cube squeezed between the pads and lifted: the contact-heavy state of the task.
    scene.reset(0)?;
    grasp_and_lift(&mut scene, &PickScript::default(), &mut |s| {
        s.step_control()
    })?;
    let held = scene.snapshot();
    let mut n = 0u64;
    let grasp_rate = rate(args.seconds, || {
        n += 1;
        if n.is_multiple_of(2400) {
            scene.restore(&held);
        }
        scene.step_physics().map_err(Into::into)
    })?;

    // Reset to a new random placement (validity check with IK, settling included).
    let mut seed = 0u64;
    let reset_rate = rate(args.seconds, || {
        seed += 1;
        scene.reset(seed).map(|_| ()).map_err(Into::into)
    })?;
    // Restoring the home snapshot alone (what a reset costs before placement and settling).
    let restore_rate = rate(args.seconds, || {
        scene.restore(&idle);
        Ok(())
    })?;

    let hz = 1.0 / scene.dt();
    if args.json {
        println!(
            "{{\"physics_hz\": {hz:.0}, \"steps_per_s_idle\": {idle_rate:.0}, \"steps_per_s_grasping\": {grasp_rate:.0}, \"resets_per_s\": {reset_rate:.0}, \"snapshot_restores_per_s\": {restore_rate:.0}}}"
        );
    } else {
        println!("full scene (FR5 + gripper + table + cube), one thread, physics at {hz:.0} Hz:");
        println!("  physics steps/s, arm holding, cube on table : {idle_rate:>10.0}");
        println!("  physics steps/s, cube grasped and lifted    : {grasp_rate:>10.0}");
        println!("  resets/s (new placement, IK check, settle)   : {reset_rate:>10.0}");
        println!("  snapshot restores/s                          : {restore_rate:>10.0}");
    }
    Ok(())
}
