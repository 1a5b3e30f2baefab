//! The grasp environment's contract: spaces, seeding, clipping, errors, rewards, termination.

use fairgrasp_env::arm::{ActionMode, Task};
use fairgrasp_env::core::EpisodeEvent;
use fairgrasp_env::scripted::ScriptedGraspPolicy;
use fairgrasp_env::sim::pick::{GraspStatus, SuccessTracker};
use fairgrasp_env::tasks::grasp::{
    GraspConfig as EnvConfig, GraspReward, ObservationPreset, RewardKind,
};
use fairgrasp_env::{Env, EnvError, GraspEnv};
use rand::SeedableRng;

mod common;
use common::scripted_episode;

fn env_with(mutate: impl FnOnce(&mut EnvConfig)) -> GraspEnv {
    let mut config = EnvConfig::default();
    mutate(&mut config);
    GraspEnv::new(config).expect("env builds")
}

#[test]
fn scripted_policy_through_step_grasps_in_joint_and_cartesian_mode() {
    for mode in [ActionMode::Joint, ActionMode::Cartesian] {
        let mut env = env_with(|c| c.control.action_mode = mode);
        let mut successes = 0;
        for seed in 0..20 {
            let (success, steps, total) = scripted_episode(&mut env, 1000 + seed);
            if success {
                successes += 1;
                assert!(steps < 100, "{mode:?}: success took {steps} steps");
                assert!(total > 10.0, "{mode:?}: success return {total}");
            }
        }
        assert!(
            successes >= 19,
            "{mode:?}: {successes}/20 scripted successes"
        );
    }
}

#[test]
fn spaces_match_the_configured_preset_and_mode() {
    for (obs, mode, dim_obs, dim_act) in [
        (ObservationPreset::Seed23, ActionMode::Joint, 23, 7),
        (ObservationPreset::Seed23, ActionMode::Cartesian, 23, 5),
        (ObservationPreset::Rich, ActionMode::Joint, 40, 7),
        (ObservationPreset::Rich, ActionMode::Cartesian, 38, 5),
    ] {
        let mut env = env_with(|c| {
            c.task.observation = obs;
            c.control.action_mode = mode;
        });
        assert_eq!(env.observation_space().dim(), dim_obs);
        assert_eq!(env.action_space().dim(), dim_act);
        assert_eq!(env.observation_space().dtype(), "float32");
        let (o, info) = env.reset(Some(1)).unwrap();
        assert_eq!(o.len(), dim_obs);
        assert!(env.observation_space().contains(&o));
        assert!(
            info.extras.is_empty(),
            "no randomisation, no parameters: {info:?}"
        );
    }
    let env = env_with(|c| c.control.max_joint_delta = 0.1);
    assert_eq!(env.action_space().high[0], 0.1);
    assert_eq!(env.action_space().low[6], -1.0);
}

#[test]
fn seed23_layout_reads_the_scene() {
    let mut env = env_with(|c| c.task.observation = ObservationPreset::Seed23);
    let (o, _) = env.reset(Some(4)).unwrap();
    let scene = env.scene();
    let q = scene.arm_positions();
    assert_eq!(&o[0..6], q.as_slice());
    let base = scene.base_pose();
    let object = base.inverse() * scene.object_state(0).pose;
    assert!((o[12] - object.translation.x as f32).abs() < 1e-6);
    assert!((o[14] - object.translation.z as f32).abs() < 1e-6);
    let quat_norm: f32 = o[15..19].iter().map(|v| v * v).sum::<f32>().sqrt();
    assert!((quat_norm - 1.0).abs() < 1e-4);
    assert!((o[22] - scene.gripper_opening()).abs() < 1e-6);
}

fn random_trajectory(seed: u64, randomize: bool, steps: usize) -> Vec<(Vec<f32>, f32, bool, bool)> {
    let mut env = env_with(|c| c.randomization.enabled = randomize);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(99);
    let mut out = Vec::new();
    let (obs, _) = env.reset(Some(seed)).unwrap();
    out.push((obs, 0.0, false, false));
    for _ in 0..steps {
        let action = env.action_space().sample(&mut rng);
        let step = env.step(&action).unwrap();
        let done = step.terminated || step.truncated;
        out.push((step.obs, step.reward, step.terminated, step.truncated));
        if done {
            let (obs, _) = env.reset(None).unwrap();
            out.push((obs, 0.0, false, false));
        }
    }
    out
}

#[test]
fn the_same_seed_gives_a_bit_identical_trajectory() {
    for randomize in [false, true] {
        let a = random_trajectory(21, randomize, 150);
        let b = random_trajectory(21, randomize, 150);
        let c = random_trajectory(22, randomize, 150);
        assert_eq!(a, b, "randomize = {randomize}");
        assert_ne!(a, c, "randomize = {randomize}");
    }
}

#[test]
fn randomization_varies_the_episode_parameters_within_their_ranges() {
    let mut env = env_with(|c| c.randomization.enabled = true);
    let ranges = env.config().randomization.clone();
    let mut masses = Vec::new();
    for _ in 0..20 {
        let (_, info) = env.reset(None).unwrap();
        let p = &info.extras;
        let mass = p.get("param/object0_mass").unwrap();
        assert!(mass >= ranges.object_mass[0] && mass <= ranges.object_mass[1]);
        assert!(p.get("param/latency_steps").unwrap() <= ranges.max_latency_steps as f32);
        for j in 0..6 {
            let d = p.get(&format!("param/joint_damping_{j}")).unwrap();
            assert!(d >= ranges.joint_damping[0] && d <= ranges.joint_damping[1]);
        }
        // The cube really has the drawn size: it rests at half its edge above the table.
        let scene = env.scene();
        let edge = match &scene.object_config(0).shape {
            fairgrasp_env::sim::scene::ObjectShape::Box { size } => size[0],
            other => panic!("{other:?}"),
        };
        assert!(edge >= 0.05 * ranges.object_scale[0] - 1e-6);
        assert!(edge <= 0.05 * ranges.object_scale[1] + 1e-6);
        let rest = scene.object_state(0).pose.translation.z - scene.table_top() as f64;
        assert!(
            (rest - edge as f64 / 2.0).abs() < 2e-3,
            "rest {rest} edge {edge}"
        );
        masses.push(mass);
    }
    assert!(masses.windows(2).any(|w| w[0] != w[1]));
    let mut plain = env_with(|_| {});
    let (_, info) = plain.reset(Some(1)).unwrap();
    assert_eq!(info.extras.get("param/object0_mass"), None);
    assert_eq!(plain.scene().object_config(0).mass, 0.1);
}

#[test]
fn actions_outside_the_box_are_clipped() {
    let mut a = env_with(|_| {});
    let mut b = env_with(|_| {});
    a.reset(Some(3)).unwrap();
    b.reset(Some(3)).unwrap();
    let wild = [5.0, -5.0, 0.3, -0.3, 1.0, 0.0, 7.0];
    let clipped = [0.05, -0.05, 0.05, -0.05, 0.05, 0.0, 1.0];
    for _ in 0..5 {
        assert_eq!(a.step(&wild).unwrap(), b.step(&clipped).unwrap());
    }
}

#[test]
fn bad_actions_are_errors_that_change_nothing() {
    let mut a = env_with(|_| {});
    let mut b = env_with(|_| {});
    assert!(
        matches!(a.step(&[0.0; 7]), Err(EnvError::Usage(_))),
        "step before reset"
    );
    a.reset(Some(8)).unwrap();
    b.reset(Some(8)).unwrap();
    let err = a.step(&[0.0; 6]).unwrap_err().to_string();
    assert!(err.contains("expected 7") && err.contains("got 6"), "{err}");
    let err = a
        .step(&[0.0, f32::NAN, 0.0, 0.0, 0.0, 0.0, 1.0])
        .unwrap_err()
        .to_string();
    assert!(err.contains("NaN"), "{err}");
    assert!(a.step(&[f32::INFINITY; 7]).is_err());
    // The rejected actions left no trace.
    let ok = [0.01, 0.0, -0.01, 0.0, 0.0, 0.0, 1.0];
    assert_eq!(a.step(&ok).unwrap(), b.step(&ok).unwrap());
}

#[test]
fn episodes_end_at_the_time_limit_and_refuse_further_steps() {
    let mut env = env_with(|c| c.task.max_episode_steps = 5);
    env.reset(Some(0)).unwrap();
    let hold = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    for i in 1..=5 {
        let step = env.step(&hold).unwrap();
        assert!(!step.terminated);
        assert_eq!(step.truncated, i == 5, "step {i}");
        assert_eq!(step.info.elapsed_steps, i);
    }
    assert!(matches!(env.step(&hold), Err(EnvError::Usage(_))));
    env.reset(None).unwrap();
    assert!(env.step(&hold).is_ok());
}

#[test]
fn hybrid_reward_terms_sum_up_and_one_time_bonuses_are_paid_once() {
    let mut env = env_with(|c| c.task.max_episode_steps = 200);
    env.reset(Some(5)).unwrap();
    let mut policy = ScriptedGraspPolicy::new(&env);
    let mut grasp_bonuses = 0;
    let mut lift_bonuses = 0;
    loop {
        let action = policy.act(&env);
        let step = env.step(&action).unwrap();
        let t = &step.info.reward_terms;
        let x = &step.info.extras;
        assert!((t.total() - step.reward).abs() < 1e-6);
        assert!((t.get("time").unwrap() + 0.01).abs() < 1e-6);
        if t.get("grasp").unwrap() > 0.0 {
            grasp_bonuses += 1;
            assert_eq!(x.get("grasped").unwrap(), 1.0);
        }
        if t.get("lift_hold").unwrap() > 0.0 {
            lift_bonuses += 1;
            assert!(step.info.success);
        }
        if x.get("ee_object_distance").unwrap() < 0.1 {
            assert_eq!(t.get("near").unwrap(), 0.5);
        }
        if step.terminated || step.truncated {
            assert!(step.info.success && step.terminated);
            break;
        }
    }
    assert_eq!((grasp_bonuses, lift_bonuses), (1, 1));
}

#[test]
fn sparse_reward_pays_only_on_success() {
    let mut env = env_with(|c| c.reward.kind = RewardKind::Sparse);
    env.reset(Some(6)).unwrap();
    let mut policy = ScriptedGraspPolicy::new(&env);
    loop {
        let step = env.step(&policy.act(&env)).unwrap();
        if step.terminated || step.truncated {
            assert!(step.info.success);
            assert_eq!(step.reward, 10.0);
            break;
        }
        assert_eq!(step.reward, 0.0);
    }
}

#[test]
fn an_object_that_leaves_the_table_terminates_with_a_penalty() {
    // A table too small for the placement area: the cube falls off the edge at reset.
    let mut env = env_with(|c| {
        c.scene.table.size = [0.3, 0.3];
        c.scene.table.center = [0.0, 0.0];
    });
    env.reset(Some(2)).unwrap();
    let step = env.step(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]).unwrap();
    assert!(step.terminated);
    assert!(step.info.events.contains(&EpisodeEvent::ObjectOffTable));
    assert_eq!(step.info.reward_terms.get("off_table").unwrap(), -10.0);
}

#[test]
fn config_errors_name_the_key() {
    for (text, key) in [
        (
            "[control]\nmax_joint_delta = 2.0\n",
            "control.max_joint_delta",
        ),
        ("[control]\naction_mode = \"teleport\"\n", "teleport"),
        ("[reward]\ngrasp_bonus = 1.0\n", "grasp_bonus"),
        (
            "[randomization]\nobject_mass = [0.3, 0.1]\n",
            "randomization.object_mass",
        ),
        (
            "[scene.gripper]\nforce_limit = -1.0\n",
            "scene.gripper.force_limit",
        ),
        ("[task]\nmax_episode_steps = 0\n", "task.max_episode_steps"),
    ] {
        let err = EnvConfig::from_toml_str(text, &[]).unwrap_err().to_string();
        assert!(err.contains(key), "{text}: {err}");
    }
    let err = EnvConfig::from_toml_str("", &["task.max_episode_stepz=3".into()])
        .unwrap_err()
        .to_string();
    assert!(err.contains("max_episode_stepz"), "{err}");
    let c = EnvConfig::from_toml_str(
        "",
        &[
            "control.action_mode=cartesian".into(),
            "randomization.enabled=true".into(),
            "scene.physics.substeps=4".into(),
        ],
    )
    .unwrap();
    assert_eq!(c.control.action_mode, ActionMode::Cartesian);
    assert!(c.randomization.enabled);
    assert_eq!(c.scene.physics.substeps, 4);
    // A saved configuration loads back unchanged.
    let back = EnvConfig::from_toml_str(&c.to_toml_string(), &[]).unwrap();
    assert_eq!(back, c);
}

#[test]
fn ansi_rendering_describes_the_state() {
    let mut env = env_with(|c| c.task.render_mode = Some(fairgrasp_env::core::RenderMode::Ansi));
    env.reset(Some(0)).unwrap();
    match env.render().unwrap() {
        Some(fairgrasp_env::core::Frame::Text(t)) => {
            assert!(t.contains("FaArmGrasp-v0") && t.contains("opening"))
        }
        other => panic!("{other:?}"),
    }
    assert!(env_with(|_| {}).render().unwrap().is_none());
}

#[test]
fn the_documented_env_config_is_the_default() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/env.toml");
    let text = std::fs::read_to_string(path).unwrap();
    assert_eq!(
        EnvConfig::from_toml_str(&text, &[]).unwrap(),
        EnvConfig::default()
    );
}

#[test]
fn staged_reward_is_never_positive_before_success_and_rises_through_the_stages() {
    let mut env = env_with(|c| c.reward.kind = RewardKind::Staged);
    env.reset(Some(9)).unwrap();
    let mut policy = ScriptedGraspPolicy::new(&env);
    let mut first = None;
    let mut best_before_success = f32::MIN;
    loop {
        let step = env.step(&policy.act(&env)).unwrap();
        let t = &step.info.reward_terms;
        assert!((t.total() - step.reward).abs() < 1e-6);
        first.get_or_insert(step.reward);
        if step.terminated || step.truncated {
            assert!(step.info.success);
            assert_eq!(t.get("success").unwrap(), 10.0);
            break;
        }
        assert!(step.reward <= 0.0 && step.reward >= -1.0, "{}", step.reward);
        if step.info.extras.get("grasped").unwrap() > 0.0 {
            assert!(t.get("grasp").unwrap() > 0.0);
        }
        best_before_success = best_before_success.max(step.reward);
    }
    // Far from the cube at first; grasped and lifted near the end (close to 0).
    assert!(first.unwrap() < -0.6, "first {first:?}");
    assert!(best_before_success > -0.05, "best {best_before_success}");

    // Knocking the cube off the table costs the worst reward for every remaining step.
    let mut env = env_with(|c| {
        c.reward.kind = RewardKind::Staged;
        c.scene.table.size = [0.3, 0.3];
        c.scene.table.center = [0.0, 0.0];
    });
    env.reset(Some(2)).unwrap();
    let step = env.step(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]).unwrap();
    assert!(step.terminated);
    assert_eq!(step.info.reward_terms.get("off_table").unwrap(), -99.0);
}

#[test]
fn a_gripper_switch_costs_its_weight_and_nothing_is_reported_at_the_default() {
    let commands = [1.0, 1.0, -1.0, -1.0, 1.0, -1.0];
    let run = |weight: f32| {
        let mut env = env_with(|c| {
            c.reward.kind = RewardKind::Staged;
            c.reward.gripper_switch = weight;
        });
        env.reset(Some(4)).unwrap();
        let zero = vec![0.0; env.action_space().dim() - 1];
        (commands.iter())
            .map(|&g| {
                let action: Vec<f32> = zero.iter().copied().chain([g]).collect();
                env.step(&action)
                    .unwrap()
                    .info
                    .reward_terms
                    .get("gripper_switch")
            })
            .collect::<Vec<_>>()
    };
    // The episode starts open: the first close and every change after it cost the weight.
    let w = 0.25;
    assert_eq!(run(w), [0.0, 0.0, -w, 0.0, -w, -w].map(Some).to_vec());
    assert!(run(0.0).iter().all(Option::is_none));
}

#[test]
fn the_alignment_term_grows_with_the_folded_yaw_near_the_object() {
    let weight = 0.5;
    let mut env = staged_cartesian(|r| r.align = weight);
    let quarter = std::f64::consts::FRAC_PI_4;
    let mut seen = Vec::new();
    for seed in 0..12 {
        env.reset(Some(seed)).unwrap();
        let step = env.step(&[0.0, 0.0, 0.0, 0.0, 1.0]).unwrap();
        let s = env.state().unwrap();
        let yaw = s.objects[0].pose.rotation.euler_angles().2 - s.tcp.rotation.euler_angles().2;
        let folded = (yaw + quarter).rem_euclid(2.0 * quarter) - quarter;
        let d = s.tcp_to_object(0).norm() as f32;
        let expected = -weight * (folded.abs() / quarter) as f32 * (1.0 - (4.0 * d).tanh());
        let got = step.info.reward_terms.get("align").unwrap();
        assert!(
            (got - expected).abs() < 1e-5,
            "seed {seed}: {got} vs {expected}"
        );
        assert!(got <= 0.0 && got >= -weight);
        seen.push(folded.abs());
    }
    // The placements' yaws spread over the folded range: the term is not a constant.
    let (lo, hi) = seen
        .iter()
        .fold((f64::MAX, 0.0f64), |(l, h), &v| (l.min(v), h.max(v)));
    assert!(lo < 0.2 && hi > 0.5, "folded yaws {seen:?}");
}

#[test]
fn turning_the_gripper_costs_with_the_heading_change_and_holding_it_costs_nothing() {
    let heading = |env: &GraspEnv| {
        let x = env.state().unwrap().tcp.rotation * nalgebra_offset(1.0, 0.0, 0.0);
        x.y.atan2(x.x)
    };
    let weight = 0.4;
    let mut env = staged_cartesian(|r| r.turn = weight);
    env.reset(Some(3)).unwrap();
    let mut before = heading(&env);
    let mut costs = Vec::new();
    // Full turns one way, then the other, then held: each step's term follows the heading.
    let held = [0.0; 12];
    for &yaw in [1.0, 1.0, 1.0, -1.0, -0.3].iter().chain(&held) {
        let step = env.step(&[0.0, 0.0, 0.0, yaw, 1.0]).unwrap();
        let now = heading(&env);
        let turned = (now - before + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        let expected = -weight * (turned.abs() / 0.1).min(1.0) as f32;
        let got = step.info.reward_terms.get("turn").unwrap();
        assert!(
            (got - expected).abs() < 1e-5,
            "yaw {yaw}: {got} vs {expected}"
        );
        costs.push(got);
        before = now;
    }
    // Full yaw steps cost most of the weight once the wrist is up to speed; once it comes to
    // rest, nearly nothing.
    assert!(costs[2] < -0.75 * weight, "{costs:?}");
    assert!(costs[costs.len() - 1] > -0.02 * weight, "{costs:?}");
    // Off by default: no term.
    let mut plain = staged_cartesian(|_| {});
    plain.reset(Some(3)).unwrap();
    let step = plain.step(&[0.0, 0.0, 0.0, 1.0, 1.0]).unwrap();
    assert_eq!(step.info.reward_terms.get("turn"), None);
    // A negative weight is named.
    let mut config = EnvConfig::default();
    config.reward.turn = -1.0;
    let err = GraspEnv::new(config).err().expect("refused");
    assert!(err.to_string().contains("reward.turn"), "{err}");
}

#[test]
fn random_shapes_draw_boxes_and_cylinders_in_range_and_show_their_size() {
    use fairgrasp_env::sim::scene::ObjectShape;
    let mut env = env_with(|c| c.shapes.enabled = true);
    let plain = env_with(|_| {});
    // Five more values: the half extents and the twofold relative yaw.
    assert_eq!(
        env.observation_space().dim(),
        plain.observation_space().dim() + 5
    );
    let ranges = env.config().shapes.clone();
    let (mut boxes, mut cylinders) = (0, 0);
    for seed in 0..30 {
        let (obs, _) = env.reset(Some(seed)).unwrap();
        let shape = env.scene().object_config(0).shape.clone();
        let half = env.scene().object_half_extents(0);
        match shape {
            ObjectShape::Box { size } => {
                boxes += 1;
                assert!(
                    size.iter()
                        .all(|s| (ranges.box_side[0]..=ranges.box_side[1]).contains(s))
                );
            }
            ObjectShape::Cylinder { radius, height } => {
                cylinders += 1;
                assert!((ranges.cylinder_radius[0]..=ranges.cylinder_radius[1]).contains(&radius));
                assert!((ranges.cylinder_height[0]..=ranges.cylinder_height[1]).contains(&height));
                assert!((half[2] - height / 2.0).abs() < 1e-4);
            }
            other => panic!("{other:?} was not asked for"),
        }
        let n = obs.len();
        assert_eq!(&obs[n - 5..n - 2], &half);
        // It rests on the table at its own half height.
        let rest = env.scene().object_state(0).pose.translation.z - env.scene().table_top() as f64;
        assert!(
            (rest - half[2] as f64).abs() < 2e-3,
            "seed {seed}: {rest} vs {half:?}"
        );
    }
    assert!(
        boxes > 5 && cylinders > 5,
        "{boxes} boxes, {cylinders} cylinders"
    );
}

/// Largest change of any arm drive target over one control step of a full-scale action, and
/// whether the scripted policy still grasps.
fn servo_run(enabled: bool) -> (f32, bool) {
    let mut env = env_with(|c| c.control.servo.enabled = enabled);
    env.reset(Some(4)).unwrap();
    let mut action = vec![1.0; env.action_space().dim()];
    action[0] = -1.0;
    let before = env.scene().arm_targets();
    env.step(&action).unwrap();
    let after = env.scene().arm_targets();
    let jump = (before.iter().zip(&after))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    let (success, _, _) = scripted_episode(&mut env, 4);
    (jump, success)
}

#[test]
fn the_servo_model_caps_the_drive_targets_and_still_lets_the_arm_grasp() {
    let (free, grasps_free) = servo_run(false);
    let (servoed, grasps_servoed) = servo_run(true);
    // From rest, four 8.3 ms periods at 720 deg/s² reach at most 720·(1+2+3+4)·dt² ≈ 0.5°.
    let dt = 1.0 / 30.0 / 4.0;
    let bound = (720.0f32 * 10.0 * dt * dt).to_radians() + 1e-6;
    assert!(servoed <= bound, "{servoed} rad > {bound} rad");
    assert!(
        free > 5.0 * bound,
        "without the model the target jumps: {free} rad"
    );
    assert!(grasps_free && grasps_servoed);
}

/// One success rule: the judge the task hands the deployment loop, the scripted pick's reading
/// of the scene against the task's rule, and training's success agree at every step.
#[test]
fn the_deployment_judge_the_scripted_picks_rule_and_training_agree() {
    let mut env = env_with(|c| c.task.success_hold_steps = 5);
    let mut successes = 0;
    for seed in 0..4 {
        env.reset(Some(2000 + seed)).unwrap();
        let mut judge = env.task().success_judge().unwrap();
        let mut tracker = SuccessTracker::new(env.config().task.success_rule());
        let mut policy = ScriptedGraspPolicy::new(&env);
        loop {
            let action = policy.act(&env);
            let step = env.step(&action).unwrap();
            let state = env.state().unwrap();
            let status = GraspStatus::of(env.scene(), 0);
            assert_eq!(status.closed_on_object, state.grasped(0));
            assert_eq!(judge.update(state), step.info.success);
            assert_eq!(tracker.update(&status), step.info.success);
            if step.terminated || step.truncated {
                successes += step.info.success as u32;
                break;
            }
        }
    }
    assert!(successes >= 3, "{successes}/4 scripted successes");
}

/// The task's defaults come from the scripted pick's rule, unchanged in training's f32.
#[test]
fn the_default_rule_is_the_scripted_picks() {
    let task = EnvConfig::default().task;
    let figures = (
        task.success_min_lift,
        task.success_max_offset,
        task.success_hold_steps,
    );
    assert_eq!(figures, (0.05, 0.08, 10));
}

#[test]
fn the_push_term_follows_the_objects_sliding_speed_until_it_is_grasped() {
    let weight = 0.4;
    let mut env = staged_cartesian(|r| r.push = weight);
    env.reset(Some(3)).unwrap();
    let cube = env.state().unwrap().objects[0].pose.translation.vector;
    // Closed fingers at the cube's height, from 10 cm on one side to 10 cm past the other:
    // the sweep shoves the cube along the table.
    let waypoints = [
        cube + nalgebra_offset(0.0, -0.10, 0.06),
        cube + nalgebra_offset(0.0, -0.10, 0.0),
        cube + nalgebra_offset(0.0, 0.10, 0.0),
    ];
    let mut pushes = Vec::new();
    for target in waypoints {
        for _ in 0..25 {
            let step = step_towards(&mut env, target, -1.0);
            let s = env.state().unwrap();
            let v = s.objects[0].linvel.xy().norm() as f32;
            let expected = if s.grasped(0) {
                0.0
            } else {
                -weight * (v / 0.05).min(1.0)
            };
            let got = step.info.reward_terms.get("push").unwrap();
            assert!((got - expected).abs() < 1e-6, "{got} vs {expected}");
            pushes.push(got);
            if step.terminated || step.truncated {
                break;
            }
        }
    }
    let strongest = pushes.iter().copied().fold(0.0f32, f32::min);
    assert!(
        strongest < -0.5 * weight,
        "the sweep never moved the cube: {pushes:?}"
    );
    // Above the resting cube (the first waypoint) the cost is next to nothing.
    assert!(pushes[3..20].iter().all(|&p| p > -1e-3), "{pushes:?}");
}

/// A staged-reward env in Cartesian mode, with `set` applied to the reward's weights.
fn staged_cartesian(set: impl FnOnce(&mut GraspReward)) -> GraspEnv {
    env_with(|c| {
        c.reward.kind = RewardKind::Staged;
        c.control.action_mode = ActionMode::Cartesian;
        set(&mut c.reward);
    })
}

/// One step moving the TCP straight towards `target` (at most 2 cm per full action), yaw held.
fn step_towards(
    env: &mut GraspEnv,
    target: fairgrasp_env::sim::rapier3d::na::Vector3<f64>,
    gripper: f32,
) -> fairgrasp_env::Step {
    let tcp = env.state().unwrap().tcp.translation.vector;
    let d = (target - tcp) / 0.02;
    let a = [d.x, d.y, d.z].map(|v| (v as f32).clamp(-1.0, 1.0));
    env.step(&[a[0], a[1], a[2], 0.0, gripper]).unwrap()
}

fn nalgebra_offset(x: f64, y: f64, z: f64) -> fairgrasp_env::sim::rapier3d::na::Vector3<f64> {
    fairgrasp_env::sim::rapier3d::na::Vector3::new(x, y, z)
}

#[test]
fn the_centre_term_costs_a_close_commanded_off_the_objects_centre() {
    let weight = 0.3;
    let run = |offset: f64| {
        let mut env = staged_cartesian(|r| r.center = weight);
        env.reset(Some(5)).unwrap();
        let s = env.state().unwrap();
        let cube = s.objects[0].pose.translation.vector;
        // `offset` off the cube's centre along the fingers' axis, above it, down, then close.
        let aside = s.tcp.rotation * nalgebra_offset(0.0, offset, 0.0);
        let plan = [
            (cube + aside + nalgebra_offset(0.0, 0.0, 0.06), 1.0, 30),
            (cube + aside, 1.0, 25),
            (cube + aside, -1.0, 5),
        ];
        let mut costs = Vec::new();
        let mut offsets = Vec::new();
        for (target, gripper, steps) in plan {
            for _ in 0..steps {
                let step = step_towards(&mut env, target, gripper);
                costs.push(step.info.reward_terms.get("center").unwrap());
                let s = env.state().unwrap();
                offsets.push(s.tcp.rotation.inverse() * s.tcp_to_object(0));
            }
        }
        (costs, offsets)
    };
    let (costs, offsets) = run(0.015);
    // Only the step that issues the close (step 55) costs, from the object's offset between
    // the pads at the step before.
    let charged: Vec<usize> = (0..costs.len()).filter(|&i| costs[i] != 0.0).collect();
    assert_eq!(charged, [55], "{costs:?}");
    let before = offsets[54];
    assert!(before.x.abs() < 0.02 && before.z.abs() < 0.02, "{before:?}");
    let expected = -weight * (before.y.abs() / 0.01).min(1.0) as f32;
    assert!(
        (costs[55] - expected).abs() < 1e-6,
        "{} vs {expected}",
        costs[55]
    );
    assert!(
        before.y.abs() > 0.005,
        "the approach ended off centre: {before:?}"
    );
    // Aimed at the centre (the Cartesian steps still leave it a few mm off): a smaller cost,
    // from the same rule.
    let (centred, offsets) = run(0.0);
    let y = offsets[54].y.abs();
    assert!(y < 0.5 * before.y.abs(), "{:?}", offsets[54]);
    let cost = -weight * (y / 0.01).min(1.0) as f32;
    assert!(
        (centred[55] - cost).abs() < 1e-6,
        "{} vs {cost}",
        centred[55]
    );
    assert!(centred[55] > expected, "{centred:?}");
}

#[test]
fn contact_stiffness_is_drawn_per_episode_and_softer_contacts_let_the_pads_sink_into_the_cube() {
    // The opening at which the fingers hold the squeezed cube, contacts at `hz`.
    let held_opening = |hz: f32| {
        let mut env = env_with(|c| c.scene.physics.contact_frequency = hz);
        env.reset(Some(2)).unwrap();
        let mut policy = ScriptedGraspPolicy::new(&env);
        let mut held = None;
        loop {
            let step = env.step(&policy.act(&env)).unwrap();
            let state = env.state().unwrap();
            if state.grasped(0) {
                held = Some(state.gripper_opening);
            }
            if step.terminated || step.truncated {
                return held.expect("the scripted grasp holds the cube");
            }
        }
    };
    let (stiff, soft) = (held_opening(300.0), held_opening(15.0));
    assert!(
        stiff - soft > 0.01,
        "held at {stiff} m (300 Hz), {soft} m (15 Hz)"
    );

    let mut env = env_with(|c| {
        c.randomization.enabled = true;
        c.randomization.contact_stiffness_scale = Some([0.05, 1.0]);
    });
    let drawn: Vec<f32> = (0..40)
        .map(|_| {
            let (_, info) = env.reset(None).unwrap();
            let hz = info.extras.get("param/contact_frequency").unwrap();
            assert_eq!(env.scene().contact_frequency(), hz);
            hz
        })
        .collect();
    assert!(
        drawn.iter().all(|hz| (14.999..=300.001).contains(hz)),
        "{drawn:?}"
    );
    // Log-uniform: about as many below the range's geometric middle (67 Hz) as above it.
    let below = drawn
        .iter()
        .filter(|&&hz| hz < (15.0f32 * 300.0).sqrt())
        .count();
    assert!(
        (10..=30).contains(&below),
        "{below} of 40 below 67 Hz: {drawn:?}"
    );
    // Without the range nothing is drawn: the scene's own contacts.
    let mut plain = env_with(|c| c.randomization.enabled = true);
    let (_, info) = plain.reset(Some(1)).unwrap();
    assert_eq!(info.extras.get("param/contact_frequency"), None);
    assert_eq!(plain.scene().contact_frequency(), 300.0);
}
