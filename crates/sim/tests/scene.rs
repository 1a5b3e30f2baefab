//! Behaviour of the grasp scene: placement, control, queries, grasping, determinism, bad input.

use fairgrasp_sim::SimError;
use fairgrasp_sim::pick::{
    GraspStatus, PickScript, SuccessRule, grasp_and_lift, run_scripted_pick,
};
use fairgrasp_sim::rapier3d::na::{Point3, Vector3};
use fairgrasp_sim::scene::{ObjectShape, Scene, SceneConfig};

fn scene() -> Scene {
    Scene::new(SceneConfig::default()).expect("default scene builds")
}

fn run_for(scene: &mut Scene, seconds: f32) {
    let steps = (seconds / scene.control_period()).ceil() as usize;
    for _ in 0..steps {
        scene.step_control().unwrap();
    }
}

#[test]
fn placements_are_uniform_in_the_area_settled_and_varied() {
    let mut scene = scene();
    let area = scene.config().placement.clone();
    let base = scene.base_pose();
    let mut xs = Vec::new();
    let mut yaws = Vec::new();
    for seed in 0..40 {
        let pose = scene.reset(seed).unwrap()[0];
        let local = base.inverse_transform_point(&Point3::from(pose.translation.vector));
        for k in 0..2 {
            let v = [local.x, local.y][k] as f32;
            assert!(
                (v - area.center[k]).abs() <= area.size[k] / 2.0 + 1e-3,
                "seed {seed}: {v} outside the area along axis {k}"
            );
        }
        // Settled on the table, not floating or sunk.
        let rest = scene.object_rest_height(0);
        assert!(
            (pose.translation.z - rest).abs() < 2e-3,
            "seed {seed}: z {} vs rest {rest}",
            pose.translation.z
        );
        let state = scene.object_state(0);
        assert!(
            Vector3::from(state.linvel).norm() < 0.01,
            "seed {seed}: still moving"
        );
        xs.push(local.x);
        yaws.push(pose.rotation.euler_angles().2);
    }
    let spread = |v: &[f64]| {
        v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min)
    };
    assert!(spread(&xs) > 0.25, "x positions barely vary: {xs:?}");
    assert!(spread(&yaws) > 3.0, "yaws barely vary: {yaws:?}");
}

#[test]
fn same_seed_gives_a_bit_identical_trajectory() {
    let record = |seed: u64| {
        let mut scene = scene();
        scene.reset(seed).unwrap();
        let mut trace = Vec::new();
        let mut step = |s: &mut Scene| {
            s.step_control()?;
            let o = s.object_state(0).pose.translation.vector;
            trace.push((s.arm_positions(), [o.x, o.y, o.z], s.gripper_opening()));
            Ok(())
        };
        grasp_and_lift(&mut scene, 0, &PickScript::default(), &mut step).unwrap();
        trace
    };
    let a = record(11);
    let b = record(11);
    let c = record(12);
    assert!(!a.is_empty());
    assert_eq!(a, b, "same seed, different trajectory");
    assert_ne!(a, c, "different seeds gave the same trajectory");
}

#[test]
fn reset_restores_the_same_start_after_an_episode() {
    let mut scene = scene();
    let first = scene.reset(5).unwrap();
    let q0 = scene.arm_positions();
    run_scripted_pick(
        &mut scene,
        0,
        &PickScript::default(),
        SuccessRule::default(),
    )
    .unwrap();
    let again = scene.reset(5).unwrap();
    assert_eq!(first, again);
    assert_eq!(q0, scene.arm_positions());
    assert_eq!(scene.time(), 0.0);
}

#[test]
fn position_control_tracks_targets_within_limits() {
    let mut scene = scene();
    scene.reset(0).unwrap();
    let mut target = scene.arm_positions();
    target[0] += 0.3;
    target[3] -= 0.2;
    scene.set_arm_targets(&target).unwrap();
    run_for(&mut scene, 1.5);
    let q = scene.arm_positions();
    for (i, (a, b)) in q.iter().zip(&target).enumerate() {
        assert!((a - b).abs() < 0.02, "joint {i}: at {a}, target {b}");
    }
    // A target beyond the limit is clamped to it.
    let limits = scene.arm_limits();
    let mut beyond = target.clone();
    beyond[0] = 10.0;
    scene.set_arm_targets(&beyond).unwrap();
    assert_eq!(scene.arm_targets()[0], limits[0].1);
}

#[test]
fn joint_limits_stop_a_joint_driven_into_them() {
    // The limit constraints are switched on only once a joint is past a limit (a speed-up):
    // full effort into the limit must still be stopped there, joint by joint and both ways.
    for (joint, upper) in [(0, true), (0, false), (3, true), (5, false)] {
        let mut scene = scene();
        scene.reset(0).unwrap();
        let (lower, upper_limit) = scene.arm_limits()[joint];
        let (limit, sign) = if upper {
            (upper_limit, 1.0)
        } else {
            (lower, -1.0)
        };
        let mut q = scene.arm_positions();
        q[joint] = limit - sign * 0.15;
        scene.set_arm_positions(&q).unwrap();
        let mut tau = vec![0.0; scene.arm_dof()];
        tau[joint] = sign * 1000.0; // capped at the joint's effort limit
        scene.set_arm_torques(&tau).unwrap();
        let mut furthest = f32::NEG_INFINITY;
        for _ in 0..30 {
            scene.step_control().unwrap();
            furthest = furthest.max(sign * (scene.arm_positions()[joint] - limit));
        }
        assert!(
            furthest > -0.01,
            "joint {joint} never reached its limit {limit} (closest {furthest})"
        );
        assert!(
            furthest < 0.03,
            "joint {joint} went {furthest} rad past its limit {limit}"
        );
    }
}

#[test]
fn torque_control_drives_joints_and_caps_at_effort() {
    let mut scene = scene();
    scene.reset(0).unwrap();
    let n = scene.arm_dof();
    // j1 turns about the vertical: gravity does not load it, so the torque alone moves it.
    let mut tau = vec![0.0; n];
    let start = scene.arm_positions()[0];
    tau[0] = 20.0;
    scene.set_arm_torques(&tau).unwrap();
    run_for(&mut scene, 0.2);
    let pushed = scene.arm_positions()[0] - start;
    assert!(pushed > 0.01, "j1 moved {pushed} rad under +20 N·m");

    let mut scene_b = self::scene();
    scene_b.reset(0).unwrap();
    tau[0] = -20.0;
    scene_b.set_arm_torques(&tau).unwrap();
    run_for(&mut scene_b, 0.2);
    assert!(scene_b.arm_positions()[0] - start < -0.01);

    // A huge command is capped at the 150 N·m effort limit: same motion as exactly 150.
    let moved = |torque: f32| {
        let mut s = self::scene();
        s.reset(0).unwrap();
        let mut tau = vec![0.0; n];
        tau[0] = torque;
        s.set_arm_torques(&tau).unwrap();
        run_for(&mut s, 0.1);
        s.arm_positions()[0]
    };
    assert_eq!(moved(1.0e6), moved(150.0));
    assert!(moved(150.0) > moved(20.0));
}

#[test]
fn gripper_opens_closes_and_reports_its_opening() {
    let mut scene = scene();
    scene.reset(0).unwrap();
    assert!((scene.gripper_opening() - scene.max_opening()).abs() < 1e-3);
    assert!(
        scene.max_opening() >= 0.08,
        "stroke {}",
        scene.max_opening()
    );
    scene.set_gripper_open(false).unwrap();
    run_for(&mut scene, 0.8);
    assert!(
        scene.gripper_opening() < 2e-3,
        "closed on nothing: {}",
        scene.gripper_opening()
    );
    scene.set_gripper_target(0.03).unwrap();
    run_for(&mut scene, 0.8);
    assert!((scene.gripper_opening() - 0.03).abs() < 2e-3);
    assert!(scene.set_gripper_target(f32::NAN).is_err());
}

#[test]
fn a_grasp_touches_with_both_pads_and_stops_the_fingers_at_the_cube() {
    let mut scene = scene();
    scene.reset(3).unwrap();
    assert_eq!(scene.finger_contacts(0), [false, false]);
    assert_eq!(scene.in_contact("cube", "table"), Some(true));
    grasp_and_lift(&mut scene, 0, &PickScript::default(), &mut |s| {
        s.step_control()
    })
    .unwrap();
    assert_eq!(scene.finger_contacts(0), [true, true]);
    assert_eq!(scene.in_contact("left_finger", "cube"), Some(true));
    assert_eq!(scene.in_contact("cube", "table"), Some(false));
    let ObjectShape::Box { size: [size, _, _] } = scene.object_config(0).shape else {
        panic!("the default object is a box");
    };
    assert!(
        (scene.gripper_opening() - size).abs() < 3e-3,
        "opening {} around a {size} m cube",
        scene.gripper_opening()
    );
    let status = GraspStatus::of(&scene, 0);
    assert!(status.closed_on_object);
    assert!(status.lift > 0.1, "lift {}", status.lift);
    assert!(status.offset < 0.02, "offset {}", status.offset);
    assert_eq!(scene.in_contact("no_such_link", "cube"), None);
}

#[test]
fn scripted_pick_succeeds_and_holds_at_240_and_120_hz() {
    for hz in [240.0, 120.0] {
        let mut config = SceneConfig::default();
        let period = config.physics.dt * config.physics.substeps as f32;
        config.physics.dt = 1.0 / hz;
        config.physics.substeps = (period * hz).round() as u32;
        let mut scene = Scene::new(config).unwrap();
        for seed in 100..106 {
            scene.reset(seed).unwrap();
            let outcome = run_scripted_pick(
                &mut scene,
                0,
                &PickScript::default(),
                SuccessRule::default(),
            )
            .unwrap();
            assert!(outcome.success, "{hz} Hz, seed {seed}: {outcome:?}");
            assert!(
                outcome.hold_drift < 0.01,
                "{hz} Hz, seed {seed}: drift {}",
                outcome.hold_drift
            );
        }
    }
}

#[test]
fn a_long_hold_while_moving_keeps_the_cube() {
    let mut scene = scene();
    scene.reset(8).unwrap();
    grasp_and_lift(&mut scene, 0, &PickScript::default(), &mut |s| {
        s.step_control()
    })
    .unwrap();
    let relative = |scene: &Scene| {
        let tcp = scene.tcp_pose();
        tcp.inverse_transform_point(&Point3::from(scene.object_state(0).pose.translation.vector))
            .coords
    };
    let start = relative(&scene);
    let hold = scene.arm_targets();
    // 30 s of slow swinging about the base and wrist.
    let steps = (30.0 / scene.control_period()).ceil() as usize;
    let mut worst: f64 = 0.0;
    for i in 0..steps {
        let t = i as f32 * scene.control_period();
        let mut q = hold.clone();
        q[0] += 0.4 * (0.5 * t).sin();
        q[5] += 0.5 * (0.7 * t).sin();
        scene.set_arm_targets(&q).unwrap();
        scene.step_control().unwrap();
        worst = worst.max((relative(&scene) - start).norm());
    }
    assert!(
        worst < 0.01,
        "cube crept {worst} m relative to the fingers over 30 s"
    );
    assert!(GraspStatus::of(&scene, 0).closed_on_object);
}

#[test]
fn link_and_object_queries_are_consistent() {
    let mut scene = scene();
    scene.reset(0).unwrap();
    let flange = scene.flange_pose();
    let tcp = scene.tcp_pose();
    // The TCP is 10 cm out of the flange along the flange z.
    let offset = flange.inverse_transform_point(&Point3::from(tcp.translation.vector));
    assert!(
        (offset.coords - Vector3::new(0.0, 0.0, 0.10)).norm() < 1e-4,
        "{offset:?}"
    );
    let fk = scene.tcp_forward(&scene.arm_positions());
    assert!((fk.translation.vector - tcp.translation.vector).norm() < 1e-3);
    assert!(scene.link_pose("no_such_link").is_none());
    // Moving the base joint gives the TCP a velocity.
    let mut q = scene.arm_positions();
    q[0] += 0.5;
    scene.set_arm_targets(&q).unwrap();
    scene.step_control().unwrap();
    let (v, _) = scene.link_velocity("tcp").unwrap();
    assert!(Vector3::from(v).norm() > 0.01);
    assert!(scene.arm_velocities()[0] > 0.01);
}

#[test]
fn ik_reaches_poses_above_the_area_and_reports_unreachable_ones() {
    let scene = scene();
    let seed = scene.arm_positions();
    let top = scene.table_top() as f64;
    for (x, y, yaw) in [(0.3, -0.2, 0.5), (0.7, 0.2, -0.7), (0.5, 0.0, 0.0)] {
        let target = scene.top_down_pose(Vector3::new(x, y, top + 0.1), yaw);
        let q = scene.solve_ik(&target, &seed).unwrap();
        let reached = scene.tcp_forward(&q);
        assert!((reached.translation.vector - target.translation.vector).norm() < 1e-3);
        for (v, (lo, hi)) in q.iter().zip(scene.arm_limits()) {
            assert!(*v >= lo && *v <= hi);
        }
    }
    let far = scene.top_down_pose(Vector3::new(3.0, 0.0, top), 0.0);
    assert!(matches!(scene.solve_ik(&far, &seed), Err(SimError::Ik(_))));
}

#[test]
fn bad_commands_are_errors_not_panics() {
    let mut scene = scene();
    scene.reset(0).unwrap();
    let n = scene.arm_dof();
    let mut q = scene.arm_positions();
    assert!(scene.set_arm_targets(&q[..n - 1]).is_err());
    q[2] = f32::NAN;
    let err = scene.set_arm_targets(&q).unwrap_err().to_string();
    assert!(err.contains("j3") && err.contains("NaN"), "{err}");
    assert!(scene.set_arm_torques(&[f32::INFINITY; 6]).is_err());
    assert!(scene.set_arm_positions(&[0.0; 3]).is_err());
    let cube = scene.object_config(0).shape.clone();
    assert!(scene.set_object_params(0, &cube, -1.0, 0.5).is_err());
    // The scene still works afterwards.
    scene.step_control().unwrap();
}

#[test]
fn invalid_settings_name_their_key() {
    type Mutation = fn(&mut SceneConfig);
    let cases: [(&str, Mutation); 6] = [
        ("physics.dt", |c| c.physics.dt = 0.0),
        ("physics.substeps", |c| c.physics.substeps = 0),
        ("objects[0].shape", |c| {
            c.objects[0].shape = ObjectShape::Box {
                size: [0.2, 0.2, 0.2],
            }
        }),
        ("gripper.force_limit", |c| c.gripper.force_limit = f32::NAN),
        ("arm.home", |c| c.arm.home = vec![0.0; 3]),
        ("table.height", |c| c.table.height = -1.0),
    ];
    for (key, mutate) in cases {
        let mut config = SceneConfig::default();
        mutate(&mut config);
        let err = Scene::new(config)
            .err()
            .unwrap_or_else(|| panic!("{key}: accepted"));
        assert!(err.to_string().contains(key), "{key}: {err}");
    }
}

#[test]
fn self_collision_option_builds_and_steps() {
    let mut config = SceneConfig::default();
    config.arm.self_collision = true;
    let mut scene = Scene::new(config).unwrap();
    scene.reset(1).unwrap();
    run_for(&mut scene, 0.5);
    scene.check_finite().unwrap();
}
