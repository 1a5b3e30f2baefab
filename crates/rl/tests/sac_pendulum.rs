//! SAC learns Pendulum-v1 within a bounded number of steps (small enough for CI in debug mode;
//! SB3 and CleanRL reach about −200 within 10–20k steps with larger networks).

mod common;

use common::{learn_for, pendulum_return, pendulums};
use fairgrasp_rl::sac::{Sac, SacConfig};

#[test]
fn sac_learns_pendulum() {
    const STEPS: u64 = 8_000;
    let n_envs = 4;
    let mut venv = pendulums(n_envs, 1);
    // Small networks and a short random phase keep the test fast; γ = 0.98 is the tuned value
    // for Pendulum in rl-zoo.
    let config = SacConfig {
        learning_rate: 1e-3,
        buffer_size: STEPS as usize,
        learning_starts: 1_000,
        net_arch: vec![64, 64],
        gamma: 0.98,
        ..SacConfig::default()
    };
    let mut sac = Sac::new(config, 3, 1, n_envs, 7).unwrap();
    let before = pendulum_return(&mut sac, 10);
    let mut episodes = Vec::new();
    learn_for(&mut sac, &mut venv, STEPS, &mut |step| {
        episodes.extend((0..step.num_envs()).filter_map(|i| step.episode(i).cloned()));
    });
    let after = pendulum_return(&mut sac, 10);
    let last: Vec<f64> = episodes
        .iter()
        .rev()
        .take(8)
        .map(|e| e.episode_return)
        .collect();
    eprintln!(
        "Pendulum return: {before:.0} before, {after:.0} after {} updates (last training \
         episodes {last:.0?})",
        sac.n_updates()
    );
    assert!(
        after > -400.0 && after > before + 300.0,
        "before {before}, after {after}"
    );
}
