//! `[control.gripper]`: the fingers move through the gripper controller's set point, as a
//! `MoveGripper` moves them on the arm, instead of jumping their target.

use fairgrasp_env::arm::ActionMode;
use fairgrasp_env::tasks::grasp::GraspConfig;
use fairgrasp_env::{Env, GraspEnv};

mod common;
use common::scripted_successes;

fn env_with(gripper: Option<[f32; 2]>) -> GraspEnv {
    let mut config = GraspConfig::default();
    config.control.action_mode = ActionMode::Joint;
    if let Some(speed) = gripper {
        config.control.gripper.enabled = true;
        config.control.gripper.speed_percent_per_s = speed;
    }
    GraspEnv::new(config).expect("env builds")
}

/// The fingers' target opening (% of the stroke) after each of `steps` closing steps.
fn closing_targets(env: &mut GraspEnv, steps: usize) -> Vec<f32> {
    env.reset(Some(3)).unwrap();
    let mut close = vec![0.0; 7];
    close[6] = -1.0;
    (0..steps)
        .map(|_| {
            env.step(&close).unwrap();
            let scene = env.scene();
            scene.gripper_target() / scene.max_opening() * 100.0
        })
        .collect()
}

#[test]
fn the_fingers_follow_the_gripper_s_set_point_at_its_speed() {
    // 300 %/s over a 1/30 s control step: 10 % of the stroke a step.
    let ramped = closing_targets(&mut env_with(Some([300.0, 300.0])), 3);
    for (k, target) in ramped.iter().enumerate() {
        let expected = 100.0 - 10.0 * (k + 1) as f32;
        assert!((target - expected).abs() < 0.5, "step {k}: {target} %");
    }
    // Off (the default): the target jumps to closed at once.
    let jumped = closing_targets(&mut env_with(None), 1);
    assert_eq!(jumped, vec![0.0]);
}

#[test]
fn a_ramped_gripper_still_grasps_and_bad_speeds_name_their_key() {
    let successes = scripted_successes(&mut env_with(Some([1200.0, 1800.0])), 0..5);
    assert!(successes >= 4, "{successes} of 5");
    for bad in [[0.0, 10.0], [20.0, 10.0], [f32::NAN, 1.0]] {
        let mut config = GraspConfig::default();
        config.control.gripper.enabled = true;
        config.control.gripper.speed_percent_per_s = bad;
        let e = GraspEnv::new(config).err().expect("refused");
        assert!(
            e.to_string()
                .contains("control.gripper.speed_percent_per_s"),
            "{e}"
        );
    }
}
