//! SAC learns Pendulum-v1 within a bounded number of steps (small enough for CI in debug mode;
//! SB3 and CleanRL reach about −200 within 10–20k steps with larger networks).

use fairgrasp_env::tasks::classic::Pendulum;
use fairgrasp_env::wrappers::RescaleAction;
use fairgrasp_env::{Env, VecEnv, VectorEnv};
use fairgrasp_rl::algorithm::Algorithm;
use fairgrasp_rl::sac::{Sac, SacConfig};

/// Mean return of the deterministic policy over `episodes` fresh Pendulum episodes.
fn evaluate(sac: &mut Sac, episodes: u64) -> f32 {
    let mut env = RescaleAction::new(Pendulum::new()).unwrap();
    let mut total = 0.0;
    for e in 0..episodes {
        let (mut obs, _) = env.reset(Some(10_000 + e)).unwrap();
        loop {
            let action = sac.predict(&obs, true).unwrap();
            let step = env.step(&action).unwrap();
            total += step.reward;
            obs = step.obs;
            if step.terminated || step.truncated {
                break;
            }
        }
    }
    total / episodes as f32
}

#[test]
fn sac_learns_pendulum() {
    const STEPS: u64 = 8_000;
    let n_envs = 4;
    let envs = (0..n_envs)
        .map(|_| RescaleAction::new(Pendulum::new()).unwrap())
        .collect();
    let mut venv = VecEnv::new(envs, 1).unwrap();
    venv.reset(Some(1)).unwrap();
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
    let before = evaluate(&mut sac, 10);
    let mut episodes = Vec::new();
    while sac.num_timesteps() < STEPS {
        let progress = 1.0 - sac.num_timesteps() as f64 / STEPS as f64;
        let stats = sac
            .learn_iteration(&mut venv, progress, &mut |step| {
                episodes.extend((0..step.num_envs()).filter_map(|i| step.episode(i).cloned()));
            })
            .unwrap();
        assert!(stats.iter().all(|(_, v)| v.is_finite()), "{stats:?}");
    }
    let after = evaluate(&mut sac, 10);
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
