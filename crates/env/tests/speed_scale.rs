//! `control.speed_scales`: an episode at the deployment's speed scale s lasts 1/s as long in
//! simulated time, with the same motion in the policy's time, as `fairgrasp deploy` moves the
//! arm.

use fairgrasp_env::arm::ActionMode;
use fairgrasp_env::tasks::grasp::GraspConfig;
use fairgrasp_env::{Env, GraspEnv};

mod common;
use common::scripted_successes;

fn env_at(scales: &[f32]) -> GraspEnv {
    let mut config = GraspConfig::default();
    config.control.action_mode = ActionMode::Joint;
    config.control.servo.enabled = true;
    config.control.gripper.enabled = true;
    config.readings.enabled = true;
    config.control.speed_scales = scales.to_vec();
    GraspEnv::new(config).expect("env builds")
}

/// Simulated time per control step, the joints after each step and the policy's and the
/// simulator's speed of joint 0 at the middle step, for one sweep of joint 0.
fn sweep(env: &mut GraspEnv) -> (f64, Vec<Vec<f32>>, f32, f32) {
    env.reset(Some(7)).unwrap();
    let start = env.scene().time();
    let mut action = vec![0.0; 7];
    action[0] = 0.05;
    action[6] = 1.0;
    let mut joints = Vec::new();
    let (mut seen, mut true_speed) = (0.0, 0.0);
    for k in 0..12 {
        env.step(&action).unwrap();
        joints.push(env.state().unwrap().q.clone());
        if k == 6 {
            seen = env.observed_state().unwrap().qd[0];
            true_speed = env.state().unwrap().qd[0];
        }
    }
    let per_step = (env.scene().time() - start) / 12.0;
    (per_step, joints, seen, true_speed)
}

#[test]
fn a_quarter_scale_takes_four_times_the_simulated_time_for_the_same_motion() {
    let (period1, joints1, seen1, true1) = sweep(&mut env_at(&[1.0]));
    let (period4, joints4, seen4, true4) = sweep(&mut env_at(&[0.25]));
    assert!(
        (period4 / period1 - 4.0).abs() < 1e-6,
        "{period1} s vs {period4} s a step"
    );
    // The set points move alike in the policy's time; only the drives' lag differs: their
    // kd/kp of 50 ms is 1.5 control steps at full scale and 0.4 at a quarter, where the arm
    // follows its set points closer (and the lead cap holds them back less).
    let travel = |joints: &[Vec<f32>]| joints[11][0] - joints1[0][0];
    for (k, (a, b)) in joints1.iter().zip(&joints4).enumerate() {
        assert!(b[0] > a[0] - 1e-3, "step {k}: {} leads {}", a[0], b[0]);
        for j in 1..6 {
            assert!(
                (a[j] - b[j]).abs() < 0.01,
                "step {k} joint {j}: {a:?} vs {b:?}"
            );
        }
    }
    let (t1, t4) = (travel(&joints1), travel(&joints4));
    assert!(t1 > 0.3 && t4 < 1.3 * t1, "{t1} rad vs {t4} rad");
    // Joint 0 moves at 0.05 rad a step, 1.5 rad/s of the policy's time: read so at both
    // scales, while the simulator's own speed at a quarter scale is a quarter.
    for seen in [seen1, seen4] {
        assert!(
            (seen - 1.5).abs() < 0.3,
            "policy-time speeds {seen1} and {seen4}"
        );
    }
    assert!((true4 / true1 - 0.25).abs() < 0.06, "{true1} vs {true4}");
}

#[test]
fn a_scripted_grasp_succeeds_at_a_quarter_scale() {
    let successes = scripted_successes(&mut env_at(&[0.25]), 0..4);
    assert!(successes >= 3, "{successes} of 4");
}

#[test]
fn a_list_of_scales_draws_one_per_episode_and_one_scale_draws_nothing() {
    let mut mixed = env_at(&[0.25, 1.0]);
    let drawn: Vec<f32> = (0..16)
        .map(|seed| {
            let (_, info) = mixed.reset(Some(seed)).unwrap();
            info.extras.get("param/speed_scale").expect("reported")
        })
        .collect();
    assert!(drawn.contains(&0.25) && drawn.contains(&1.0), "{drawn:?}");
    let (_, info) = env_at(&[0.5]).reset(Some(0)).unwrap();
    assert_eq!(info.extras.get("param/speed_scale"), None);
}

#[test]
fn bad_scales_name_their_key() {
    let cases: [(&[f32], bool); 5] = [
        (&[], true),
        (&[0.0], true),
        (&[1.5], true),
        (&[f32::NAN], true),
        (&[0.25], false),
    ];
    for (scales, readings) in cases {
        let mut config = GraspConfig::default();
        config.readings.enabled = readings;
        config.control.speed_scales = scales.to_vec();
        let e = GraspEnv::new(config).err().expect("refused");
        assert!(e.to_string().contains("control.speed_scales"), "{e}");
    }
}

/// With `observe_speed_scale` the observation ends with each episode's drawn scale, and is
/// otherwise the one without it.
#[test]
fn a_policy_that_observes_the_speed_scale_sees_each_episodes() {
    let plain_dim = env_at(&[0.25, 1.0]).observation_space().dim();
    let mut config = GraspConfig::default();
    config.control.action_mode = ActionMode::Joint;
    config.control.servo.enabled = true;
    config.readings.enabled = true;
    config.control.speed_scales = vec![0.25, 1.0];
    config.control.observe_speed_scale = true;
    let mut env = GraspEnv::new(config).unwrap();
    assert_eq!(env.observation_space().dim(), plain_dim + 1);
    let mut seen = Vec::new();
    for seed in 0..8 {
        let (obs, info) = env.reset(Some(seed)).unwrap();
        let scale = info
            .extras
            .get("param/speed_scale")
            .expect("the scale is reported");
        assert_eq!(obs.last(), Some(&scale), "seed {seed} at reset");
        let mut action = vec![0.0; 7];
        action[6] = 1.0;
        let step = env.step(&action).unwrap();
        assert_eq!(step.obs.last(), Some(&scale), "seed {seed} after a step");
        seen.push(scale);
    }
    assert!(seen.contains(&0.25) && seen.contains(&1.0), "{seen:?}");
}
