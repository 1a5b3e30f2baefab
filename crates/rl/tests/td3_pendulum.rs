//! TD3 learns Pendulum-v1 within a bounded number of steps (small enough for CI in debug mode;
//! the same budget as SAC's test).

mod common;

use common::{learn_for, pendulum_return, pendulums};
use fairgrasp_rl::td3::{Td3, Td3Config};

#[test]
fn td3_learns_pendulum() {
    const STEPS: u64 = 8_000;
    let n_envs = 4;
    let mut venv = pendulums(n_envs, 1);
    let config = Td3Config {
        learning_rate: 1e-3,
        buffer_size: STEPS as usize,
        learning_starts: 1_000,
        net_arch: vec![64, 64],
        gamma: 0.98,
        ..Td3Config::default()
    };
    let mut td3 = Td3::new(config, 3, 1, n_envs, 7).unwrap();
    let before = pendulum_return(&mut td3, 10);
    learn_for(&mut td3, &mut venv, STEPS, &mut |_| {});
    let after = pendulum_return(&mut td3, 10);
    eprintln!(
        "Pendulum return: {before:.0} before, {after:.0} after {} critic updates",
        td3.n_updates()
    );
    assert!(
        after > -400.0 && after > before + 300.0,
        "before {before}, after {after}"
    );
}
