//! Helpers shared by the env's integration tests.

use fairgrasp_env::scripted::ScriptedGraspPolicy;
use fairgrasp_env::{Env, GraspEnv};
use std::ops::Range;

/// Runs the scripted policy for one episode; returns (success, steps, return).
pub fn scripted_episode(env: &mut GraspEnv, seed: u64) -> (bool, u32, f32) {
    env.reset(Some(seed)).unwrap();
    let mut policy = ScriptedGraspPolicy::new(env);
    let mut total = 0.0;
    loop {
        let action = policy.act(env);
        assert!(
            env.action_space().contains(&action),
            "scripted action outside the space"
        );
        let step = env.step(&action).unwrap();
        total += step.reward;
        if step.terminated || step.truncated {
            return (step.info.success, step.info.elapsed_steps, total);
        }
    }
}

/// How many of the scripted policy's episodes over `seeds` succeed.
#[allow(dead_code)] // not every test file counts successes
pub fn scripted_successes(env: &mut GraspEnv, seeds: Range<u64>) -> u32 {
    seeds.map(|seed| scripted_episode(env, seed).0 as u32).sum()
}
