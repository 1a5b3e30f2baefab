//! Helpers the learning tests share.

// Each test file is its own crate and uses only some of these.
#![allow(dead_code)]

use fairgrasp_env::tasks::classic::Pendulum;
use fairgrasp_env::wrappers::RescaleAction;
use fairgrasp_env::{Env, VecEnv, VecStep, VectorEnv};
use fairgrasp_rl::algorithm::Algorithm;

/// Mean return over `episodes` fresh episodes of `env` (seeds 10 000, 10 001, …), acting with
/// `act(observation)`.
pub fn mean_return<E: Env>(
    env: &mut E,
    episodes: u64,
    mut act: impl FnMut(&[f32]) -> Vec<f32>,
) -> f32 {
    let mut total = 0.0;
    for e in 0..episodes {
        let (mut obs, _) = env.reset(Some(10_000 + e)).unwrap();
        loop {
            let step = env.step(&act(&obs)).unwrap();
            total += step.reward;
            obs = step.obs;
            if step.terminated || step.truncated {
                break;
            }
        }
    }
    total / episodes as f32
}

/// Mean return of `learner`'s deterministic policy over `episodes` Pendulum episodes.
pub fn pendulum_return(learner: &mut impl Algorithm, episodes: u64) -> f32 {
    let mut env = RescaleAction::new(Pendulum::new()).unwrap();
    mean_return(&mut env, episodes, |obs| {
        learner.predict(obs, true).unwrap()
    })
}

/// `n` Pendulums acting in `[-1, 1]`, reset with `seed`.
pub fn pendulums(n: usize, seed: u64) -> VecEnv<RescaleAction<Pendulum>> {
    let envs = (0..n)
        .map(|_| RescaleAction::new(Pendulum::new()).unwrap())
        .collect();
    let mut venv = VecEnv::new(envs, 1).unwrap();
    venv.reset(Some(seed)).unwrap();
    venv
}

/// Learn iterations until `learner` has taken `steps` environment steps, checking that every
/// logged value is finite.
pub fn learn_for<A: Algorithm, V: VectorEnv>(
    learner: &mut A,
    venv: &mut V,
    steps: u64,
    on_step: &mut dyn FnMut(&VecStep<'_>),
) {
    while learner.num_timesteps() < steps {
        let progress = 1.0 - learner.num_timesteps() as f64 / steps as f64;
        let stats = learner.learn_iteration(venv, progress, on_step).unwrap();
        assert!(stats.iter().all(|(_, v)| v.is_finite()), "{stats:?}");
    }
}
