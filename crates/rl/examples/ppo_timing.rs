//! Times PPO's work that is not the environment: the rollout's policy inference and the update,
//! on a synthetic rollout (no physics), with the design's settings (`configs/ppo_seed.toml`:
//! 4 envs, n_steps 2048, batch 256, 10 epochs, [64, 64] tanh; 23 observation values and 7
//! actions as in the `seed23` grasp task). Prints a checksum of the trained weights, so two
//! builds can be checked for identical arithmetic as well as timed.
//!
//! ```sh
//! cargo run --release -p fairgrasp-rl --example ppo_timing [-- ITERATIONS [OBS ACT ENVS STEPS BATCH EPOCHS HIDDEN]]
//! ```
//!
//! `PPO_TIMING_AUTOGRAD=1` runs the update through candle's autograd instead of the loss
//! written out (`fairgrasp_rl::ppo::fused_loss`).

use fairgrasp_env::random::standard_normal;
use fairgrasp_rl::algorithm::Algorithm;
use fairgrasp_rl::ppo::{Ppo, PpoConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // As `fairgrasp` does: candle's matrix products on one thread.
    if std::env::var_os("RAYON_NUM_THREADS").is_none() {
        // SAFETY: nothing else runs yet.
        unsafe { std::env::set_var("RAYON_NUM_THREADS", "1") };
    }
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse())
        .collect::<Result<_, _>>()?;
    let arg = |i: usize, default: usize| args.get(i).copied().unwrap_or(default);
    let iterations = arg(0, 3);
    let (obs_dim, act_dim, n_envs) = (arg(1, 23), arg(2, 7), arg(3, 4));
    let hidden = arg(7, 64);
    let config = PpoConfig {
        n_steps: arg(4, 2048),
        batch_size: arg(5, 256),
        n_epochs: arg(6, 10),
        net_arch: vec![hidden, hidden],
        ..PpoConfig::default()
    };
    let mut ppo = Ppo::new(config.clone(), obs_dim, act_dim, n_envs, 42)?;
    ppo.written_out_loss = std::env::var_os("PPO_TIMING_AUTOGRAD").is_none();
    let mut data_rng = ChaCha8Rng::seed_from_u64(7);
    let mut obs = vec![0.0f32; n_envs * obs_dim];

    let (mut act_time, mut act_calls, mut gae_time, mut update_time) = (0.0, 0usize, 0.0, 0.0);
    for _ in 0..iterations {
        ppo.buffer.clear();
        while !ppo.buffer.is_full() {
            for v in obs.iter_mut() {
                *v = standard_normal(&mut data_rng);
            }
            let t = Instant::now();
            let out = ppo.policy.act(&obs, false, &mut ppo.rng)?;
            act_time += t.elapsed().as_secs_f64();
            act_calls += 1;
            let rewards: Vec<f32> = (0..n_envs)
                .map(|_| data_rng.random::<f32>() - 1.0)
                .collect();
            let starts: Vec<bool> = (0..n_envs)
                .map(|_| data_rng.random::<f32>() < 0.01)
                .collect();
            ppo.buffer.push(
                &obs,
                &out.actions,
                &rewards,
                &starts,
                &out.values,
                &out.log_probs,
                &[],
            );
        }
        let t = Instant::now();
        let last = ppo.policy.values(&obs)?;
        ppo.buffer.compute_returns_and_advantages(
            &last,
            &vec![false; n_envs],
            config.gamma,
            config.gae_lambda,
        );
        gae_time += t.elapsed().as_secs_f64();
        let t = Instant::now();
        ppo.update(1.0)?;
        update_time += t.elapsed().as_secs_f64();
    }
    let samples = config.n_steps * n_envs;
    let minibatches = iterations * config.n_epochs * samples.div_ceil(config.batch_size);
    println!(
        "inference: {act_calls} calls of {n_envs} observations, {:.1} us per call ({:.3} s)",
        1e6 * act_time / act_calls as f64,
        act_time
    );
    println!(
        "GAE: {:.3} ms per rollout; update: {minibatches} minibatch steps of {}, {:.3} ms each ({:.3} s per update)",
        1e3 * gae_time / iterations as f64,
        config.batch_size,
        1e3 * update_time / minibatches as f64,
        update_time / iterations as f64
    );
    // FNV-1a over the weights' bits, in name order.
    let weights = ppo.weights()?;
    let mut names: Vec<&String> = weights.keys().collect();
    names.sort();
    let mut hash = 0xcbf2_9ce4_8422_2325u64;
    for name in names {
        for v in weights[name].flatten_all()?.to_vec1::<f32>()? {
            for byte in v.to_bits().to_le_bytes() {
                hash = (hash ^ byte as u64).wrapping_mul(0x0100_0000_01b3);
            }
        }
    }
    println!("weights checksum {hash:016x}");
    Ok(())
}
