//! TD3 learns Pendulum-v1 within a bounded number of steps (small enough for CI in debug mode;
//! the same budget as SAC's test).

use fairgrasp_env::tasks::classic::Pendulum;
use fairgrasp_env::wrappers::RescaleAction;
use fairgrasp_env::{Env, VecEnv, VectorEnv};
use fairgrasp_rl::algorithm::Algorithm;
use fairgrasp_rl::td3::{Td3, Td3Config};

/// Mean return of the deterministic policy over `episodes` fresh Pendulum episodes.
fn evaluate(td3: &mut Td3, episodes: u64) -> f32 {
    let mut env = RescaleAction::new(Pendulum::new()).unwrap();
    let mut total = 0.0;
    for e in 0..episodes {
        let (mut obs, _) = env.reset(Some(10_000 + e)).unwrap();
        loop {
            let step = env.step(&td3.predict(&obs, true).unwrap()).unwrap();
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
fn td3_learns_pendulum() {
    const STEPS: u64 = 8_000;
    let n_envs = 4;
    let envs = (0..n_envs)
        .map(|_| RescaleAction::new(Pendulum::new()).unwrap())
        .collect();
    let mut venv = VecEnv::new(envs, 1).unwrap();
    venv.reset(Some(1)).unwrap();
    let config = Td3Config {
        learning_rate: 1e-3,
        buffer_size: STEPS as usize,
        learning_starts: 1_000,
        net_arch: vec![64, 64],
        gamma: 0.98,
        ..Td3Config::default()
    };
    let mut td3 = Td3::new(config, 3, 1, n_envs, 7).unwrap();
    let before = evaluate(&mut td3, 10);
    while td3.num_timesteps() < STEPS {
        let progress = 1.0 - td3.num_timesteps() as f64 / STEPS as f64;
        let stats = td3
            .learn_iteration(&mut venv, progress, &mut |_| {})
            .unwrap();
        assert!(stats.iter().all(|(_, v)| v.is_finite()), "{stats:?}");
    }
    let after = evaluate(&mut td3, 10);
    eprintln!(
        "Pendulum return: {before:.0} before, {after:.0} after {} critic updates",
        td3.n_updates()
    );
    assert!(
        after > -400.0 && after > before + 300.0,
        "before {before}, after {after}"
    );
}
