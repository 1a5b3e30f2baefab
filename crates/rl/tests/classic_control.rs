//! The algorithms learn classic-control tasks within a bounded number of steps (small enough for
//! CI; the long versions are benchmarks).

mod common;

use common::mean_return;
use fairgrasp_env::tasks::classic::PointReach;
use fairgrasp_env::{Env, VecEnv, VectorEnv};
use fairgrasp_rl::ppo::{Ppo, PpoConfig};
use rand::SeedableRng;

/// Mean deterministic return of the PPO policy over `episodes` PointReach episodes.
fn evaluate(ppo: &Ppo, episodes: u64) -> f32 {
    let mut env = PointReach::new();
    let space = env.action_space().clone();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    mean_return(&mut env, episodes, |obs| {
        let mut action = ppo.policy.act(obs, true, &mut rng).unwrap().actions;
        space.clip(&mut action);
        action
    })
}

#[test]
fn ppo_learns_point_reach() {
    let n_envs = 8;
    let envs = (0..n_envs).map(|_| PointReach::new()).collect();
    let mut venv = VecEnv::new(envs, 1).unwrap();
    venv.reset(Some(1)).unwrap();
    let config = PpoConfig {
        n_steps: 128,
        batch_size: 256,
        n_epochs: 10,
        learning_rate: 1e-3,
        ..PpoConfig::default()
    };
    let mut ppo = Ppo::new(config, 6, 2, n_envs, 7).unwrap();
    let before = evaluate(&ppo, 20);
    while ppo.num_timesteps < 60_000 {
        ppo.collect_rollout(&mut venv, &mut |_| {}).unwrap();
        let progress = 1.0 - ppo.num_timesteps as f64 / 60_000.0;
        let stats = ppo.update(progress).unwrap();
        assert!(stats.policy_loss.is_finite() && stats.value_loss.is_finite());
    }
    let after = evaluate(&ppo, 20);
    eprintln!("PointReach return: {before:.1} before, {after:.1} after");
    assert!(
        after > -15.0 && after > before + 15.0,
        "before {before}, after {after}"
    );
}
