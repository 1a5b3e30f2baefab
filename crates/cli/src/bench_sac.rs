//! `fairgrasp bench sac`: SAC gradient steps per second at the default grasp training's sizes
//! (networks, batch, the task's observation and action sizes), on a replay buffer of random
//! transitions. `bench/run` sets it beside SB3's `SAC.train` on the same sizes
//! (`bench/harness/reference_bench.py sac-gradient-steps`).

use anyhow::{Result, ensure};
use fairgrasp_env::random::standard_normal;
use fairgrasp_env::{Env, registry};
use fairgrasp_rl::sac::Sac;
use fairgrasp_rl::train::TrainConfig;
use rand::{Rng, SeedableRng};
use std::time::Instant;

#[derive(clap::Args)]
pub struct SacBenchArgs {
    /// Seconds of wall time of the measurement.
    #[arg(long, default_value_t = 3.0)]
    pub seconds: f64,
    /// Random transitions in the replay buffer.
    #[arg(long, default_value_t = 10_000)]
    pub transitions: usize,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Override a setting of the default SAC training (`--set sac.batch_size=512`).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
}

pub fn run(args: &SacBenchArgs) -> Result<()> {
    ensure!(args.seconds > 0.0, "--seconds must be positive");
    ensure!(args.transitions > 0, "--transitions must be at least 1");
    let table =
        fairgrasp_rl::configs::builtin_table(fairgrasp_env::ENV_ID, fairgrasp_rl::Algo::Sac)?;
    let config = TrainConfig::from_toml_str(&table.to_string(), &args.overrides)?;
    let env = registry::make(&config.env_id, &config.env)?;
    let (obs_dim, act_dim) = (
        env.observation_space().shape[0],
        env.action_space().low.len(),
    );
    let fairgrasp_rl::AlgoConfig::Sac(mut sac_config) = config.algo else {
        anyhow::bail!("--set algo=… must keep SAC: this benchmark times SAC's update");
    };
    sac_config.buffer_size = args.transitions;
    let mut sac = Sac::new(sac_config.clone(), obs_dim, act_dim, 1, 0)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    for _ in 0..args.transitions {
        let obs: Vec<f32> = (0..obs_dim).map(|_| standard_normal(&mut rng)).collect();
        let next: Vec<f32> = (0..obs_dim).map(|_| standard_normal(&mut rng)).collect();
        let action: Vec<f32> = (0..act_dim).map(|_| rng.random_range(-1.0..1.0)).collect();
        sac.replay_buffer_mut()
            .push(&obs, &action, rng.random(), &next, false);
    }
    // Warm-up (allocations, caches), then whole calls of 10 steps until the time is up.
    sac.train(10)?;
    let (start, cpu_start) = (Instant::now(), process_cpu_seconds());
    let mut steps = 0u64;
    while start.elapsed().as_secs_f64() < args.seconds {
        sac.train(10)?;
        steps += 10;
    }
    let per_s = steps as f64 / start.elapsed().as_secs_f64();
    // Per second of this process's CPU time too: on a busy host, wall time measures the load.
    let per_cpu_s = match (cpu_start, process_cpu_seconds()) {
        (Some(a), Some(b)) if b > a => format!("{:.1}", steps as f64 / (b - a)),
        _ => "null".into(),
    };
    let threads = std::env::var("RAYON_NUM_THREADS").unwrap_or_default();
    if args.json {
        println!(
            "{{\"gradient_steps_per_s\": {per_s:.1}, \"gradient_steps_per_cpu_s\": {per_cpu_s}, \"batch_size\": {}, \"net_arch\": {:?}, \"obs_dim\": {obs_dim}, \"act_dim\": {act_dim}, \"rayon_threads\": \"{threads}\"}}",
            sac_config.batch_size, sac_config.net_arch
        );
    } else {
        println!(
            "SAC, batch {}, {:?} networks, {obs_dim} observation and {act_dim} action values, \
             RAYON_NUM_THREADS={threads}:",
            sac_config.batch_size, sac_config.net_arch
        );
        println!("  {per_s:.1} gradient steps/s ({per_cpu_s} per second of CPU time)");
    }
    Ok(())
}

/// User and system CPU time of this process so far (Linux's `/proc/self/stat`, in clock ticks
/// of 1/100 s), or `None` elsewhere.
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces) in brackets; utime and stime are
    // the 14th and 15th fields of the line.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}
