//! `[control.drives]`: the arm's drives between the servo set points and the joints — a delay
//! and a lag per joint, as `fairgrasp sysid` identifies them.

use fairgrasp_env::tasks::grasp::GraspConfig as EnvConfig;
use fairgrasp_env::{Env, EnvError, GraspEnv};

mod common;
use common::scripted_episode;

fn env_with(mutate: impl FnOnce(&mut EnvConfig)) -> GraspEnv {
    let mut config = EnvConfig::default();
    config.control.servo.enabled = true;
    mutate(&mut config);
    GraspEnv::new(config).expect("env builds")
}

fn with_drives(delay_ms: f64, tau_ms: f64, integral: bool) -> GraspEnv {
    env_with(|c| {
        c.control.drives.enabled = true;
        c.control.drives.delay_ms = [delay_ms; 6];
        c.control.drives.tau_ms = [tau_ms; 6];
        c.control.drives.integral = integral;
    })
}

/// The joints' targets after each of `steps` steps of one full-scale action from seed 4.
fn targets(env: &mut GraspEnv, steps: usize) -> Vec<Vec<f32>> {
    env.reset(Some(4)).unwrap();
    let mut action = vec![1.0; env.action_space().dim()];
    action[0] = -1.0;
    (0..steps)
        .map(|_| {
            env.step(&action).unwrap();
            env.scene().arm_targets()
        })
        .collect()
}

fn largest_move(from: &[f32], to: &[f32]) -> f32 {
    from.iter()
        .zip(to)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max)
}

#[test]
fn a_delay_holds_the_joints_back_and_a_lag_smooths_them() {
    // (The integral action off: it would move the targets by the sag it learns.)
    let mut plain = env_with(|_| {});
    plain.reset(Some(4)).unwrap();
    let start = plain.scene().arm_targets();
    let free = targets(&mut plain, 6);
    // A 40 ms delay outlasts the first 33 ms control step: the joints' targets have not moved.
    let delayed = targets(&mut with_drives(40.0, 0.0, false), 6);
    assert!(largest_move(&start, &delayed[0]) < 1e-6, "{delayed:?}");
    assert!(largest_move(&start, &free[0]) > 1e-3, "{free:?}");
    // Later they follow the same set points, 40 ms (1.2 steps) behind: by the sixth step they
    // have moved further than the free joints had by the fourth.
    let moved = |t: &[Vec<f32>], k: usize| largest_move(&start, &t[k]);
    assert!(moved(&delayed, 5) > moved(&free, 3), "{delayed:?}");
    assert!(moved(&delayed, 5) < moved(&free, 5));
    // A lag alone starts at once but slower.
    let lagged = targets(&mut with_drives(0.0, 60.0, false), 6);
    assert!(moved(&lagged, 0) > 0.0 && moved(&lagged, 0) < 0.5 * moved(&free, 0));
}

#[test]
fn the_scripted_policy_still_grasps_through_identified_drives() {
    // The strict twin's drives: 8 ms delay, 15 ms lag, and the integral action.
    let mut env = with_drives(8.0, 15.0, true);
    let successes = (0..5)
        .filter(|&s| scripted_episode(&mut env, 100 + s).0)
        .count();
    assert!(successes >= 4, "{successes} of 5");
}

#[test]
fn drives_switched_off_change_nothing() {
    let mut off = env_with(|c| {
        c.control.drives.delay_ms = [30.0; 6];
        c.control.drives.tau_ms = [30.0; 6];
        c.control.drives.scale = [0.5, 1.5];
    });
    let mut default = env_with(|_| {});
    for seed in [1, 2] {
        assert_eq!(
            scripted_episode(&mut off, seed),
            scripted_episode(&mut default, seed)
        );
        assert_eq!(targets(&mut off, 3), targets(&mut default, 3));
    }
}

#[test]
fn each_episode_draws_its_scale_and_reports_it() {
    let mut env = env_with(|c| {
        c.control.drives.enabled = true;
        c.control.drives.delay_ms = [8.0; 6];
        c.control.drives.scale = [0.5, 1.5];
    });
    let scales: Vec<f32> = (0..6)
        .map(|seed| {
            env.reset(Some(seed))
                .unwrap()
                .1
                .extras
                .get("param/drive_scale")
                .unwrap()
        })
        .collect();
    assert!(scales.iter().all(|s| (0.5..1.5).contains(s)), "{scales:?}");
    assert!(scales.windows(2).any(|w| w[0] != w[1]), "{scales:?}");
    // The same seed draws the same scale.
    let again = env
        .reset(Some(0))
        .unwrap()
        .1
        .extras
        .get("param/drive_scale")
        .unwrap();
    assert_eq!(again, scales[0]);
}

#[test]
fn bad_drive_settings_are_named() {
    let build = |mutate: fn(&mut EnvConfig)| {
        let mut config = EnvConfig::default();
        config.control.servo.enabled = true;
        config.control.drives.enabled = true;
        mutate(&mut config);
        match GraspEnv::new(config) {
            Err(EnvError::Config { key, problem }) => format!("{key}: {problem}"),
            Err(e) => panic!("{e}"),
            Ok(_) => panic!("accepted"),
        }
    };
    let no_servo = build(|c| c.control.servo.enabled = false);
    assert!(no_servo.contains("control.drives.enabled") && no_servo.contains("servo"));
    let long = build(|c| c.control.drives.delay_ms[2] = 900.0);
    assert!(
        long.contains("delay_ms") && long.contains("joint 3"),
        "{long}"
    );
    let nan = build(|c| c.control.drives.tau_ms[0] = f64::NAN);
    assert!(nan.contains("tau_ms") && nan.contains("joint 1"), "{nan}");
    let scale = build(|c| c.control.drives.scale = [2.0, 1.0]);
    assert!(scale.contains("control.drives.scale"), "{scale}");
}

/// The joints' largest distance (rad) from the home pose after 30 still steps from a reset.
fn sag_at_rest(integral: bool) -> f32 {
    let mut env = with_drives(8.0, 15.0, integral);
    env.reset(Some(4)).unwrap();
    let home = env.scene().config().arm.home.clone();
    let still = vec![0.0; env.action_space().dim()];
    for _ in 0..30 {
        env.step(&still).unwrap();
    }
    largest_move(&home, &env.scene().arm_positions())
}

#[test]
fn the_drives_integral_takes_out_the_sag_as_the_twins_does() {
    // The simulated joints have no gravity compensation: held still, they sag below their set
    // points; the integral (at most 0.5°) brings them back, and in the same way pushes a joint
    // held off its set point harder the longer it is held.
    let (with, without) = (sag_at_rest(true), sag_at_rest(false));
    assert!(
        without > 0.1f32.to_radians(),
        "the joints sag {without} rad"
    );
    assert!(
        with < 0.3 * without,
        "{with} rad with the integral, {without} without"
    );
}
