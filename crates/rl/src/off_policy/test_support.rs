//! What the unit tests of SAC and TD3 share: small environments, weight snapshots, a filled
//! replay buffer, and the checks both learners must pass alike.

use crate::algorithm::{Algorithm, TensorMap};
use crate::buffers::ReplayBuffer;
use crate::error::{Result, RlError};
use candle_core::DType;
use fairgrasp_env::tasks::classic::Pendulum;
use fairgrasp_env::wrappers::RescaleAction;
use fairgrasp_env::{VecEnv, VectorEnv};
use std::collections::HashMap;

/// Tensors by name as plain values.
pub(crate) type Snapshot = HashMap<String, Vec<f32>>;

/// `n` Pendulums acting in `[-1, 1]`, reset with `seed`.
pub(crate) fn pendulums(n: usize, seed: u64) -> VecEnv<RescaleAction<Pendulum>> {
    let envs = (0..n)
        .map(|_| RescaleAction::new(Pendulum::new()).unwrap())
        .collect();
    let mut venv = VecEnv::new(envs, 1).unwrap();
    venv.reset(Some(seed)).unwrap();
    venv
}

/// Deep copies of tensors (a variable's tensor shares its storage, which training changes).
pub(crate) fn snapshot(map: &TensorMap) -> Snapshot {
    map.iter()
        .map(|(k, t)| {
            let values = t.flatten_all().unwrap().to_dtype(DType::F32).unwrap();
            (k.clone(), values.to_vec1().unwrap())
        })
        .collect()
}

/// A snapshot of the learner's weights.
pub(crate) fn weights_of(learner: &impl Algorithm) -> Snapshot {
    snapshot(&learner.weights().unwrap())
}

/// The tensors of `snap` whose names start with `prefix`, sorted by name.
pub(crate) fn group(snap: &Snapshot, prefix: &str) -> Vec<(String, Vec<f32>)> {
    let mut out: Vec<_> = snap
        .iter()
        .filter(|(k, _)| k.starts_with(prefix))
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    out.sort_by(|a, b| a.0.cmp(&b.0));
    assert!(!out.is_empty(), "no tensors under {prefix}");
    out
}

/// Pushes `n` made-up Pendulum-shaped transitions (3 observation values, 1 action), some of
/// them terminal.
pub(crate) fn fill_replay(buffer: &mut ReplayBuffer, n: usize) {
    for i in 0..n {
        let x = i as f32 / n as f32;
        buffer.push(&[x, -x, 0.5], &[x - 0.5], x, &[x, x, 0.0], i % 7 == 0);
    }
}

/// The error of a learn iteration on a Pendulum left acting in `[-2, 2]`.
pub(crate) fn unit_box_error(learner: &mut impl Algorithm) -> String {
    let mut venv = VecEnv::new(vec![Pendulum::new()], 1).unwrap();
    venv.reset(Some(0)).unwrap();
    learner
        .learn_iteration(&mut venv, 1.0, &mut |_| {})
        .unwrap_err()
        .to_string()
}

/// `validate` accepts `valid` and refuses each case with an error naming `{section}.{key}`.
pub(crate) fn assert_validate_names_keys<C>(
    section: &str,
    validate: impl Fn(&C, usize) -> Result<()>,
    valid: &C,
    cases: Vec<(&str, C)>,
) {
    validate(valid, 4).unwrap();
    for (key, config) in cases {
        match validate(&config, 4) {
            Err(RlError::Config { key: k, .. }) => assert_eq!(k, format!("{section}.{key}")),
            other => panic!("{key}: {other:?}"),
        }
    }
}

/// What a learner does in 6 iterations on fresh Pendulums: the logged stats, a stochastic
/// action, its weights then, its gradient steps.
type Continuation = (Vec<Vec<(&'static str, f32)>>, Vec<f32>, Snapshot, u64);

fn continue_learning<A: Algorithm>(learner: &mut A, n_updates: impl Fn(&A) -> u64) -> Continuation {
    let mut venv = pendulums(2, 50);
    let stats = (0..6)
        .map(|_| {
            learner
                .learn_iteration(&mut venv, 1.0, &mut |_| {})
                .unwrap()
        })
        .collect();
    let actions = learner
        .predict(&[0.5f32, -0.3, 1.0, 0.1, 0.9, -2.0], false)
        .unwrap();
    (stats, actions, weights_of(learner), n_updates(learner))
}

/// A `fresh()` learner (another seed) given `trained`'s weights and training state continues
/// bit-exactly like `trained`, one given only the weights does not (optimiser moments, replay
/// buffer, random stream are in the state), and a state lacking any of `required` is an error
/// naming it.
pub(crate) fn assert_training_state_resumes<A: Algorithm>(
    trained: &mut A,
    fresh: impl Fn() -> A,
    n_updates: impl Fn(&A) -> u64 + Copy,
    required: &[&str],
) {
    let weights = trained.weights().unwrap();
    let state = trained.training_state().unwrap();
    let mut resumed = fresh();
    resumed.load_weights(&weights).unwrap();
    resumed.load_training_state(&state).unwrap();
    resumed.set_num_timesteps(trained.num_timesteps());
    let mut weights_only = fresh();
    weights_only.load_weights(&weights).unwrap();
    weights_only.set_num_timesteps(trained.num_timesteps());
    assert_eq!(weights_of(trained), weights_of(&resumed));

    let want = continue_learning(trained, n_updates);
    assert!(!want.0.iter().all(|s| s.is_empty()));
    assert_eq!(want, continue_learning(&mut resumed, n_updates));
    let parted = continue_learning(&mut weights_only, n_updates);
    assert_ne!(want.0, parted.0);
    assert_ne!(want.1, parted.1);

    for key in required {
        let mut broken = state.clone();
        broken.remove(*key).unwrap();
        let err = resumed
            .load_training_state(&broken)
            .unwrap_err()
            .to_string();
        // Optimiser errors name the key under its prefix (`adam.m.… (under `actor_opt.`)`).
        assert!(
            err.contains(&key[key.find("adam").unwrap_or(0)..]),
            "{key}: {err}"
        );
    }
}
