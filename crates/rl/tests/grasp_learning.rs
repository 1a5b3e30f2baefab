//! The README's main job learns: the default `fairgrasp train` (the built-in PPO settings of
//! FaArmGrasp-v0, its default seed) reaches its stop rule, and the model it keeps grasps on
//! held-out episodes (≥ 90 of 100). The whole run, not fewer steps: what is checked is that
//! the shipped settings learn the grasp, so the test trains what a user's first command trains.
//! It stops at about 350k steps (30 s on a quiet AVX-512 host, 105 s on an AMD EPYC 2-vCPU
//! one, in the release build); the cap below only bounds a run that stopped learning.

use fairgrasp_env::ENV_ID;
use fairgrasp_rl::Policy;
use fairgrasp_rl::configs::builtin_table;
use fairgrasp_rl::evaluation::evaluate;
use fairgrasp_rl::train::{HELD_OUT_SEED_BASE, TrainConfig, train};

#[test]
fn the_default_training_reaches_its_stop_rule_and_its_model_grasps_held_out_episodes() {
    let table = builtin_table(ENV_ID, fairgrasp_rl::Algo::Ppo).unwrap();
    let config = TrainConfig::from_toml_str(
        &table.to_string(),
        &["total_timesteps=1000000".into(), "checkpoint_freq=0".into()],
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let summary = train(&config, dir.path(), |_| {}).unwrap();
    eprintln!(
        "default training: {} steps in {:.0} s ({:.0} steps/s), best {:?}",
        summary.num_timesteps, summary.seconds, summary.fps, summary.best
    );
    assert!(
        summary.reached_threshold,
        "no stop within {} steps; best evaluation {:?}",
        summary.num_timesteps, summary.best
    );
    let mut policy = Policy::load(&dir.path().join("best")).unwrap();
    let env = fairgrasp_rl::model::env_table(policy.env_config()).unwrap();
    let held_out = evaluate(
        &mut |obs: &[f32], _: Option<&[u8]>| policy.act(obs, true),
        ENV_ID,
        &env,
        100,
        HELD_OUT_SEED_BASE,
    )
    .unwrap();
    // Fresh runs of these settings score 95–99 % held-out (README); the same seed takes
    // another floating-point path on a host with other vector instructions, hence the margin.
    assert!(
        held_out.success_rate >= 0.90,
        "{:.0} % of 100 held-out episodes grasped",
        100.0 * held_out.success_rate
    );
}
