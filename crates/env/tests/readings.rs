//! `[readings]`: the policy's state built from synthesized controller readings, as the
//! deployment builds it; the true state stays the judge.

use fairgrasp_env::arm::ActionMode;
use fairgrasp_env::scripted::ScriptedGraspPolicy;
use fairgrasp_env::tasks::grasp::GraspConfig;
use fairgrasp_env::{Env, GraspEnv};

fn env_with(mutate: impl FnOnce(&mut GraspConfig)) -> GraspEnv {
    let mut config = GraspConfig::default();
    config.readings.enabled = true;
    mutate(&mut config);
    GraspEnv::new(config).expect("env builds")
}

#[test]
fn the_policy_sees_the_controller_s_view_and_a_scripted_grasp_still_succeeds() {
    let mut env = env_with(|c| c.readings.state_age_ms = [0.0, 15.0]);
    let (mut successes, mut held_seen) = (0, 0);
    for seed in 0..10 {
        env.reset(Some(seed)).unwrap();
        let mut policy = ScriptedGraspPolicy::new(&env);
        loop {
            let step = env.step(&policy.act(&env)).unwrap();
            let seen = env.observed_state().unwrap();
            let truth = env.state().unwrap();
            // The gripper in the controller's whole percent; the pads inferred, both at once.
            let percent = seen.gripper_opening / seen.gripper_max_opening * 100.0;
            assert!((percent - percent.round()).abs() < 1e-3, "{percent}");
            let pads = seen.objects[0].pad_contacts;
            assert_eq!(pads[0], pads[1]);
            held_seen += (pads[0] && truth.grasped(0)) as u32;
            if step.terminated || step.truncated {
                successes += step.info.success as u32;
                break;
            }
        }
    }
    assert!(successes >= 9, "{successes} of 10");
    assert!(
        held_seen > 0,
        "the estimator never saw the grasp the simulator had"
    );
}

#[test]
fn readings_older_than_the_step_s_end_lag_the_true_joints() {
    // Joint 0 turning at the action's full 0.05 rad per step: about 1.5 rad/s.
    let lag = |age_ms: f32| {
        let mut env = env_with(|c| {
            c.control.action_mode = ActionMode::Joint;
            c.readings.state_age_ms = [age_ms, age_ms];
        });
        env.reset(Some(1)).unwrap();
        let mut action = vec![0.0; 7];
        action[0] = 0.05;
        action[6] = 1.0;
        for _ in 0..10 {
            env.step(&action).unwrap();
        }
        let (seen, truth) = (env.observed_state().unwrap(), env.state().unwrap());
        (truth.q[0] - seen.q[0], truth.qd[0])
    };
    let (now, _) = lag(0.0);
    assert!(now.abs() < 1e-5, "{now}");
    // 12.5 ms: three physics substeps at 240 Hz.
    let (behind, speed) = lag(12.5);
    let expected = speed * 0.0125;
    assert!(expected > 0.005, "the joint barely moves: {speed} rad/s");
    assert!(
        (behind / expected - 1.0).abs() < 0.3,
        "{behind} rad behind, {expected} expected"
    );
}

#[test]
fn the_privileged_state_is_the_true_state_s_observation_and_the_policy_never_reads_it() {
    // Per step: the policy's observation, `info.privileged`, and what it should be.
    let run = |privileged: bool| {
        let mut env = env_with(|c| {
            c.readings.state_age_ms = [0.0, 15.0];
            c.readings.privileged = privileged;
            c.control.speed_scales = vec![0.25, 1.0];
        });
        let dim = env.observation_space().dim();
        assert_eq!(env.privileged_dim(), if privileged { dim + 1 } else { 0 });
        let mut steps = Vec::new();
        for seed in [3, 4] {
            let (obs, info) = env.reset(Some(seed)).unwrap();
            let scale = info.extras.get("param/speed_scale").unwrap();
            let zeros = vec![0.0; env.action_space().dim()];
            let mut want = env.observation_of(env.state().unwrap(), &zeros, scale);
            want.push(scale);
            steps.push((obs, info.privileged, want));
            let mut policy = ScriptedGraspPolicy::new(&env);
            for _ in 0..40 {
                let action = policy.act(&env);
                let step = env.step(&action).unwrap();
                let high = &env.action_space().high;
                let normalised: Vec<f32> = action.iter().zip(high).map(|(a, h)| a / h).collect();
                let mut want = env.observation_of(env.state().unwrap(), &normalised, scale);
                want.push(scale);
                steps.push((step.obs, step.info.privileged, want));
                if step.terminated || step.truncated {
                    break;
                }
            }
        }
        steps
    };
    let (with, without) = (run(true), run(false));
    // The policy's observations are the same bits with and without the privileged state.
    let observations = |steps: &[(Vec<f32>, Vec<f32>, Vec<f32>)]| -> Vec<Vec<f32>> {
        steps.iter().map(|s| s.0.clone()).collect()
    };
    assert_eq!(observations(&with), observations(&without));
    assert!(
        without
            .iter()
            .all(|(_, privileged, _)| privileged.is_empty())
    );
    for (i, (_, privileged, want)) in with.iter().enumerate() {
        assert_eq!(privileged, want, "step {i}");
    }
    // Both speed scales were drawn, and the privileged state holds what the readings do not.
    let scales: Vec<f32> = with.iter().map(|s| *s.1.last().unwrap()).collect();
    assert!(
        scales.contains(&0.25) && scales.contains(&1.0),
        "{scales:?}"
    );
    let differing = with
        .iter()
        .filter(|(obs, p, _)| obs[..] != p[..obs.len()])
        .count();
    assert!(differing > with.len() / 2, "{differing} of {}", with.len());
}

/// In a pixel mode `info.privileged` is what a state policy of the same settings observes —
/// through the readings — so that a distillation's teacher trained with them labels the
/// states it learnt on; `readings.privileged` still asks for the true state.
#[test]
fn a_pixel_mode_gives_the_teacher_the_state_policy_s_observation_through_the_readings() {
    use fairgrasp_env::arm::camera::ObsMode;
    let settings = |c: &mut GraspConfig| {
        c.readings.state_age_ms = [0.0, 15.0];
        c.control.speed_scales = vec![0.25, 1.0];
    };
    let mut state_env = env_with(settings);
    let pixel_env = |privileged: bool| {
        env_with(|c| {
            settings(c);
            c.camera.mode = ObsMode::RgbState;
            c.camera.width = 16;
            c.camera.height = 16;
            c.readings.privileged = privileged;
        })
    };
    let (mut pixel, mut critic) = (pixel_env(false), pixel_env(true));
    let (mut steps, mut apart_from_truth) = (0, 0);
    for seed in [3, 4] {
        let (obs, _) = state_env.reset(Some(seed)).unwrap();
        let (_, info) = pixel.reset(Some(seed)).unwrap();
        critic.reset(Some(seed)).unwrap();
        assert_eq!(info.privileged[..obs.len()], obs[..], "reset {seed}");
        let mut policy = ScriptedGraspPolicy::new(&state_env);
        for _ in 0..40 {
            let action = policy.act(&state_env);
            let want = state_env.step(&action).unwrap();
            let got = pixel.step(&action).unwrap();
            let truth = critic.step(&action).unwrap();
            let dim = want.obs.len();
            assert_eq!(got.info.privileged[..dim], want.obs[..], "seed {seed}");
            assert_eq!(got.info.privileged.len(), dim + 1);
            steps += 1;
            apart_from_truth += (truth.info.privileged != got.info.privileged) as usize;
            if want.terminated || want.truncated {
                break;
            }
        }
    }
    // The readings differ from the truth (age, inferred pads, whole percent) most steps.
    assert!(
        apart_from_truth > steps / 2,
        "{apart_from_truth} of {steps}"
    );
}
