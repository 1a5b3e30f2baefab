//! Scenes with several objects of every shape kind, and bins: building, resting, grasping,
//! placement checks, random layouts, per-episode changes and bad settings.

use fairgrasp_sim::pick::{PickScript, SuccessRule, run_scripted_pick};
use fairgrasp_sim::rapier3d::na::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use fairgrasp_sim::rapier3d::parry::query;
use fairgrasp_sim::rapier3d::prelude::{Pose, SharedShape, Vector};
use fairgrasp_sim::scene::{
    BinConfig, ObjectConfig, ObjectShape, PhysicalParams, Scene, SceneConfig,
};
use std::path::PathBuf;

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/objects")
        .join(name)
}

fn object(name: &str, shape: ObjectShape) -> ObjectConfig {
    ObjectConfig {
        name: name.into(),
        shape,
        ..ObjectConfig::default()
    }
}

fn box_of(size: [f32; 3]) -> ObjectShape {
    ObjectShape::Box { size }
}

/// Hexagonal prism, 34.6 mm across flats, 50 mm tall (the file is in millimetres).
fn hex_prism() -> ObjectShape {
    ObjectShape::Mesh {
        path: data("hex_prism.obj"),
        scale: 0.001,
    }
}

/// Square frustum: 40 mm base, 30 mm top, 40 mm tall (ASCII STL in millimetres).
fn frustum() -> ObjectShape {
    ObjectShape::Mesh {
        path: data("frustum.stl"),
        scale: 0.001,
    }
}

fn scene_with(objects: Vec<ObjectConfig>, bins: Vec<BinConfig>) -> Scene {
    Scene::new(SceneConfig {
        objects,
        bins,
        ..SceneConfig::default()
    })
    .expect("scene builds")
}

fn run_for(scene: &mut Scene, seconds: f32) {
    for _ in 0..(seconds / scene.dt()).ceil() as usize {
        scene.step_physics().unwrap();
    }
}

/// World pose at arm-base-frame `x, y` and world height `z`, no rotation.
fn at(scene: &Scene, x: f64, y: f64, z: f64) -> Isometry3<f64> {
    let p = scene.base_pose() * Point3::new(x, y, 0.0);
    Isometry3::translation(p.x, p.y, z)
}

/// The test's own collision shape of a primitive object, in the object's frame.
fn independent_shape(shape: &ObjectShape) -> (SharedShape, Pose) {
    match shape {
        ObjectShape::Box { size } => (
            SharedShape::cuboid(size[0] / 2.0, size[1] / 2.0, size[2] / 2.0),
            Pose::IDENTITY,
        ),
        ObjectShape::Cylinder { radius, height } => (
            SharedShape::cylinder(height / 2.0, *radius),
            Pose::rotation(Vector::X * std::f32::consts::FRAC_PI_2),
        ),
        ObjectShape::Sphere { radius } => (SharedShape::ball(*radius), Pose::IDENTITY),
        ObjectShape::Mesh { .. } => unreachable!("primitives only"),
    }
}

fn to_pose(iso: &Isometry3<f64>) -> Pose {
    let t = iso.translation.vector;
    let q = iso.rotation.quaternion();
    Pose::from_parts(
        Vector::new(t.x as f32, t.y as f32, t.z as f32),
        fairgrasp_sim::rapier3d::prelude::Rotation::from_xyzw(
            q.i as f32, q.j as f32, q.k as f32, q.w as f32,
        )
        .normalize(),
    )
}

#[test]
fn every_shape_kind_rests_upright_at_its_rest_height() {
    let cases = [
        ("box", box_of([0.04, 0.03, 0.06]), 0.03),
        (
            "cylinder",
            ObjectShape::Cylinder {
                radius: 0.02,
                height: 0.06,
            },
            0.03,
        ),
        ("sphere", ObjectShape::Sphere { radius: 0.025 }, 0.025),
        ("hex", hex_prism(), 0.025),
        ("frustum", frustum(), 0.02),
    ];
    for (name, shape, half_height) in cases {
        let mut scene = scene_with(vec![object(name, shape)], Vec::new());
        assert!(
            (scene.object_half_height(0) - half_height).abs() < 1e-4,
            "{name}: half height {} instead of {half_height}",
            scene.object_half_height(0)
        );
        assert!(
            (scene.object_rest_height(0) - scene.table_top() as f64 - half_height).abs() < 1e-4
        );
        for seed in 0..3 {
            let pose = scene.reset(seed).unwrap()[0];
            let rest = scene.object_rest_height(0);
            assert!(
                (pose.translation.z - rest).abs() < 2e-3,
                "{name}, seed {seed}: z {} vs rest height {rest}",
                pose.translation.z
            );
            let up = pose.rotation * Vector3::z();
            assert!(
                up.z > 0.999,
                "{name}, seed {seed}: tipped over, up = {up:?}"
            );
            assert!(!scene.object_off_table(0));
            assert_eq!(scene.in_contact(name, "table"), Some(true), "{name}");
        }
    }
}

#[test]
fn the_scripted_pick_grasps_each_shape_that_fits() {
    // (shape, the width the fingers should close to)
    let cases = [
        (box_of([0.04; 3]), 0.04),
        (
            ObjectShape::Cylinder {
                radius: 0.02,
                height: 0.06,
            },
            0.04,
        ),
        (ObjectShape::Sphere { radius: 0.025 }, 0.05),
        (hex_prism(), 0.0346),
        // Too long to grasp end to end: the fingers must close across the 35 mm side.
        (box_of([0.12, 0.035, 0.04]), 0.035),
    ];
    for (shape, width) in cases {
        let label = format!("{shape:?}");
        let mut scene = scene_with(vec![object("item", shape)], Vec::new());
        for seed in [1, 2, 3] {
            scene.reset(seed).unwrap();
            let outcome = run_scripted_pick(
                &mut scene,
                0,
                &PickScript::default(),
                SuccessRule::default(),
            )
            .unwrap();
            assert!(outcome.success, "{label}, seed {seed}: {outcome:?}");
            assert!(
                (scene.gripper_opening() as f64 - width).abs() < 3e-3,
                "{label}, seed {seed}: fingers stopped at {} m around a {width} m width",
                scene.gripper_opening()
            );
        }
    }
}

#[test]
fn objects_dropped_above_a_bin_land_inside_it_and_bins_move() {
    let bin = BinConfig::default();
    let mut scene = scene_with(
        vec![
            ObjectConfig::default(),
            object("ball", ObjectShape::Sphere { radius: 0.02 }),
        ],
        vec![bin.clone()],
    );
    scene.restore_home(&PhysicalParams::default(), &[]).unwrap();
    let floor = scene.bin_pose(0);
    let top = scene.table_top() as f64;
    assert!((floor.translation.z - top - bin.wall_thickness as f64).abs() < 1e-6);
    let wall_top = top + bin.wall_height as f64;

    let above = floor.translation.vector + Vector3::new(0.01, -0.02, 0.0);
    let drop = Isometry3::translation(above.x, above.y, wall_top + 0.1);
    scene.set_object_pose(0, &drop).unwrap();
    let outside = at(&scene, 0.45, -0.15, scene.object_rest_height(1) + 0.001);
    scene.set_object_pose(1, &outside).unwrap();
    run_for(&mut scene, 1.0);
    assert!(scene.object_in_bin(0, 0));
    assert!(!scene.object_in_bin(1, 0));
    let z = scene.object_state(0).pose.translation.z;
    let on_floor = floor.translation.z + scene.object_half_height(0);
    assert!(
        (z - on_floor).abs() < 2e-3,
        "cube at z {z}, floor rest {on_floor}"
    );
    assert_eq!(scene.in_contact("cube", "bin"), Some(true));
    assert_eq!(scene.in_contact("cube", "table"), Some(false));
    assert_eq!(scene.in_contact("ball", "bin"), Some(false));

    // Moved for an episode; the next home restore puts it back.
    scene.restore_home(&PhysicalParams::default(), &[]).unwrap();
    scene.set_bin_xy(0, [0.55, -0.2]).unwrap();
    assert_eq!(scene.bins()[0].center, [0.55, -0.2]);
    let moved = scene.bin_pose(0);
    let expected = at(&scene, 0.55, -0.2, 0.0).translation.vector;
    assert!((moved.translation.vector.xy() - expected.xy()).norm() < 1e-5);
    // The old spot is now free, the new one is not.
    let old_spot = at(
        &scene,
        bin.center[0] as f64,
        bin.center[1] as f64,
        top + 0.026,
    );
    assert!(scene.pose_is_free(0, &old_spot));
    let new_spot = Isometry3::translation(moved.translation.x, moved.translation.y, top + 0.026);
    assert!(!scene.pose_is_free(0, &new_spot));
    let drop = Isometry3::translation(moved.translation.x, moved.translation.y, wall_top + 0.1);
    scene.set_object_pose(0, &drop).unwrap();
    run_for(&mut scene, 1.0);
    assert!(scene.object_in_bin(0, 0));
    scene.restore_home(&PhysicalParams::default(), &[]).unwrap();
    assert_eq!(scene.bins()[0].center, bin.center);
    assert!((scene.bin_pose(0).translation.vector - floor.translation.vector).norm() < 1e-9);

    let overhang = scene.set_bin_xy(0, [2.0, 0.0]).unwrap_err().to_string();
    assert!(overhang.contains("overhang"), "{overhang}");
    assert!(scene.set_bin_xy(0, [f32::NAN, 0.0]).is_err());
}

#[test]
fn an_object_dropped_on_a_wall_does_not_pass_through_it() {
    let bin = BinConfig::default();
    let mut scene = scene_with(vec![ObjectConfig::default()], vec![bin.clone()]);
    scene.restore_home(&PhysicalParams::default(), &[]).unwrap();
    let floor = scene.bin_pose(0);
    let t = bin.wall_thickness;
    let wall_x = (bin.inner_size[0] + t) as f64 / 2.0;
    // The test's own copy of the +x wall.
    let wall = SharedShape::cuboid(t / 2.0, bin.inner_size[1] / 2.0 + t, bin.wall_height / 2.0);
    let wall_pose =
        to_pose(&(floor * Translation3::new(wall_x, 0.0, (bin.wall_height / 2.0 - t) as f64)));
    let cube = SharedShape::cuboid(0.025, 0.025, 0.025);
    // Just outside the wall's middle line, 30 cm up: it lands on the wall top and tips.
    let start = floor * Point3::new(wall_x + 0.008, 0.0, 0.3);
    scene
        .set_object_pose(0, &Isometry3::translation(start.x, start.y, start.z))
        .unwrap();
    let mut deepest: f32 = 0.0;
    let mut touched = false;
    for _ in 0..(1.5 / scene.dt()) as usize {
        scene.step_physics().unwrap();
        touched |= scene.in_contact("cube", "bin") == Some(true);
        let pose = to_pose(&scene.object_state(0).pose);
        if let Some(c) =
            query::contact(&pose, cube.as_ref(), &wall_pose, wall.as_ref(), 0.0).unwrap()
        {
            deepest = deepest.min(c.dist);
        }
    }
    assert!(touched, "the cube never hit the bin");
    assert!(
        deepest > -0.003,
        "the cube sank {} m into the wall",
        -deepest
    );
    // It ends on the table outside, or on the floor inside: not on or in the wall.
    let c = scene.object_state(0).pose.translation.vector;
    let local = floor.inverse_transform_point(&Point3::from(c));
    assert!((local.x - wall_x).abs() > 0.02, "resting at {local:?}");
    assert!(local.z < 0.03, "resting at {local:?}");
}

#[test]
fn the_gripper_collides_with_bin_walls() {
    let bin = BinConfig::default();
    let mut scene = scene_with(vec![ObjectConfig::default()], vec![bin.clone()]);
    scene.restore_home(&PhysicalParams::default(), &[]).unwrap();
    let floor = scene.bin_pose(0);
    let wall_x = (bin.inner_size[0] + bin.wall_thickness) as f64 / 2.0;
    let wall_top_z = floor.translation.z + (bin.wall_height - bin.wall_thickness) as f64;
    // Push the closed fingers 3 cm into the wall top (the fingertips are 2 cm past the TCP).
    scene.set_gripper_open(false).unwrap();
    let over = floor * Point3::new(wall_x, 0.0, 0.0);
    let yaw = scene.tcp_pose().rotation.euler_angles().2;
    let target = scene.top_down_pose(Vector3::new(over.x, over.y, wall_top_z - 0.01), yaw);
    let q = scene.solve_ik(&target, &scene.arm_positions()).unwrap();
    let start = scene.arm_positions();
    let n = (2.0 / scene.control_period()) as usize;
    for i in 1..=n {
        let s = i as f32 / n as f32;
        let blend: Vec<f32> = start.iter().zip(&q).map(|(a, b)| a + (b - a) * s).collect();
        scene.set_arm_targets(&blend).unwrap();
        scene.step_control().unwrap();
    }
    let touching = ["left_finger", "right_finger"]
        .iter()
        .any(|f| scene.in_contact(f, "bin") == Some(true));
    assert!(touching, "the fingers do not touch the bin");
    let tcp_z = scene.tcp_pose().translation.z;
    assert!(
        tcp_z > wall_top_z + 0.015,
        "the TCP reached {tcp_z}, through the wall top at {wall_top_z}"
    );
}

#[test]
fn pose_is_free_refuses_overlaps_and_reachability_is_checked() {
    let mut scene = scene_with(
        vec![ObjectConfig::default(), object("other", box_of([0.05; 3]))],
        vec![BinConfig::default()],
    );
    scene.restore_home(&PhysicalParams::default(), &[]).unwrap();
    let z = scene.object_rest_height(0) + 0.001;
    let spot = at(&scene, 0.5, -0.1, z);
    assert!(scene.pose_is_free(1, &spot), "a free spot is refused");
    scene.set_object_pose(0, &spot).unwrap();
    assert!(
        !scene.pose_is_free(1, &spot),
        "the same spot is accepted twice"
    );
    assert!(
        !scene.pose_is_free(1, &at(&scene, 0.53, -0.1, z)),
        "3 cm apart"
    );
    // Touching within the 2 mm clearance is refused, 5 mm apart is accepted.
    assert!(!scene.pose_is_free(1, &at(&scene, 0.551, -0.1, z)));
    assert!(scene.pose_is_free(1, &at(&scene, 0.555, -0.1, z)));
    // A rotated neighbour whose corner reaches into the cube.
    let turned = at(&scene, 0.56, -0.1, z)
        * UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_4);
    assert!(!scene.pose_is_free(1, &turned));
    // An object is never in its own way.
    assert!(scene.pose_is_free(0, &spot));
    // The bin and the robot are obstacles.
    let bin = scene.bin_pose(0).translation.vector;
    assert!(!scene.pose_is_free(1, &Isometry3::translation(bin.x, bin.y, z)));
    let finger = scene.link_pose("left_finger").unwrap().translation.vector;
    assert!(!scene.pose_is_free(1, &Isometry3::translation(finger.x, finger.y, finger.z)));
    // Parked objects are not.
    scene.park_objects();
    assert!(scene.pose_is_free(1, &spot));

    assert!(scene.reachable_from_above(&spot));
    assert!(!scene.reachable_from_above(&at(&scene, 1.4, 0.0, z)));
}

/// The smallest gap between two of the objects at `poses` (m), from the test's own shapes.
fn closest_pair(colliders: &[(SharedShape, Pose)], poses: &[Isometry3<f64>]) -> f32 {
    let mut closest = f32::INFINITY;
    for i in 0..poses.len() {
        for j in i + 1..poses.len() {
            let (a, la) = &colliders[i];
            let (b, lb) = &colliders[j];
            let d = query::distance(
                &(to_pose(&poses[i]) * la),
                a.as_ref(),
                &(to_pose(&poses[j]) * lb),
                b.as_ref(),
            )
            .unwrap()
            .distance;
            closest = closest.min(d);
        }
    }
    closest
}

#[test]
fn random_resets_place_five_objects_apart_on_the_table() {
    let shapes = [
        box_of([0.05; 3]),
        ObjectShape::Cylinder {
            radius: 0.02,
            height: 0.06,
        },
        ObjectShape::Sphere { radius: 0.025 },
        box_of([0.03, 0.07, 0.04]),
        ObjectShape::Cylinder {
            radius: 0.03,
            height: 0.04,
        },
    ];
    let objects: Vec<ObjectConfig> = shapes
        .iter()
        .enumerate()
        .map(|(i, s)| object(&format!("o{i}"), s.clone()))
        .collect();
    let mut scene = scene_with(objects, Vec::new());
    let area = scene.config().placement.clone();
    let base = scene.base_pose();
    let colliders: Vec<(SharedShape, Pose)> = shapes.iter().map(independent_shape).collect();
    for seed in 0..50 {
        let poses = scene.reset(seed).unwrap();
        assert_eq!(poses.len(), 5);
        for (i, pose) in poses.iter().enumerate() {
            assert!(!scene.object_parked(i));
            let local = base.inverse_transform_point(&Point3::from(pose.translation.vector));
            for k in 0..2 {
                let v = [local.x, local.y][k] as f32;
                assert!((v - area.center[k]).abs() <= area.size[k] / 2.0 + 0.01);
            }
            let rest = scene.object_rest_height(i);
            assert!(
                (pose.translation.z - rest).abs() < 2e-3,
                "seed {seed}, object {i}: z {} vs rest {rest}",
                pose.translation.z
            );
        }
        let closest = closest_pair(&colliders, &poses);
        assert!(closest > 0.0, "seed {seed}: two objects overlap");
    }
    // Deterministic per seed.
    let a = scene.reset(7).unwrap();
    let b = scene.reset(7).unwrap();
    assert_eq!(a, b);
    // A clearance keeps every pair that far apart (up to the settling after the drop).
    let mut config = scene.config().clone();
    config.placement.clearance = 0.03;
    let mut spaced = Scene::new(config).unwrap();
    let closest = (0..20)
        .map(|seed| closest_pair(&colliders, &spaced.reset(seed).unwrap()))
        .fold(f32::INFINITY, f32::min);
    assert!((0.028..0.06).contains(&closest), "closest pair {closest} m");
    // Crowded: a layout that leaves no room for the last object is drawn again whole.
    let mut config = scene.config().clone();
    config.placement.size = [0.2, 0.2];
    config.placement.clearance = 0.035;
    let mut crowded = Scene::new(config).unwrap();
    for seed in 0..40 {
        let poses = crowded
            .reset(seed)
            .unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        let closest = closest_pair(&colliders, &poses);
        assert!(closest > 0.03, "seed {seed}: closest pair {closest} m");
    }
}

#[test]
fn object_params_change_for_one_episode_and_are_checked() {
    let mut scene = scene_with(vec![ObjectConfig::default()], Vec::new());
    let params = PhysicalParams::default();
    let ball = ObjectShape::Sphere { radius: 0.02 };
    scene.restore_home(&params, &[]).unwrap();
    scene.set_object_params(0, &ball, 0.3, 0.5).unwrap();
    let in_force = scene.object_config(0);
    assert_eq!(
        (&in_force.shape, in_force.mass, in_force.friction),
        (&ball, 0.3, 0.5)
    );
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(3);
    let poses = scene.place_objects_at_random(&mut rng).unwrap();
    assert!((scene.object_rest_height(0) - scene.table_top() as f64 - 0.02).abs() < 1e-6);
    assert!((poses[0].translation.z - scene.object_rest_height(0)).abs() < 2e-3);
    assert_eq!(scene.time(), 0.0, "settling advanced the clock");

    // A mesh for the next episode, then back to the configuration.
    scene.restore_home(&params, &[]).unwrap();
    assert_eq!(scene.object_config(0), &ObjectConfig::default());
    scene.set_object_params(0, &hex_prism(), 0.1, 0.8).unwrap();
    assert!((scene.object_half_height(0) - 0.025).abs() < 1e-4);
    scene.restore_home(&params, &[]).unwrap();
    assert!((scene.object_half_height(0) - 0.025).abs() < 1e-6);
    assert_eq!(scene.object_config(0), &ObjectConfig::default());

    let errors = [
        (
            ObjectShape::Sphere { radius: -0.01 },
            0.1,
            0.5,
            "shape.radius",
        ),
        (box_of([0.1, 0.1, 0.05]), 0.1, 0.5, "90 mm gripper opening"),
        (
            ObjectShape::Mesh {
                path: data("hex_prism.obj"),
                scale: 0.01,
            },
            0.1,
            0.5,
            "90 mm gripper opening",
        ),
        (
            ObjectShape::Mesh {
                path: data("missing.stl"),
                scale: 0.001,
            },
            0.1,
            0.5,
            "missing.stl",
        ),
        (ball.clone(), f32::NAN, 0.5, "mass"),
        (ball.clone(), 0.1, -1.0, "friction"),
    ];
    for (shape, mass, friction, expected) in errors {
        let err = scene
            .set_object_params(0, &shape, mass, friction)
            .unwrap_err()
            .to_string();
        assert!(err.contains(expected), "{shape:?}: {err}");
        assert!(
            err.contains("cube"),
            "the error does not name the object: {err}"
        );
    }
    // A refused change leaves the object as it was.
    assert_eq!(scene.object_config(0), &ObjectConfig::default());
    assert!((scene.object_half_height(0) - 0.025).abs() < 1e-6);
}

#[test]
fn parked_objects_are_out_of_play() {
    let mut scene = scene_with(
        vec![
            ObjectConfig::default(),
            object("ball", ObjectShape::Sphere { radius: 0.02 }),
        ],
        Vec::new(),
    );
    // A new scene and a home restore start with every object parked.
    assert!(scene.object_parked(0) && scene.object_parked(1));
    scene.reset(0).unwrap();
    assert!(!scene.object_parked(0) && !scene.object_parked(1));
    assert_eq!(scene.in_contact("ball", "table"), Some(true));
    scene.park_objects();
    let parked = [scene.object_state(0).pose, scene.object_state(1).pose];
    run_for(&mut scene, 0.5);
    for (i, pose) in parked.iter().enumerate() {
        assert!(scene.object_parked(i));
        assert!(scene.object_off_table(i));
        assert_eq!(&scene.object_state(i).pose, pose, "a parked object moved");
    }
    assert_eq!(scene.in_contact("cube", "table"), Some(false));
    assert_eq!(scene.in_contact("ball", "table"), Some(false));
    // Parked objects keep apart from each other.
    let gap = (parked[0].translation.vector - parked[1].translation.vector).norm();
    assert!(gap > 0.05, "parked {gap} m apart");
    // Names: objects, the table, robot links; unknown names are None.
    assert_eq!(scene.object_index("ball"), Some(1));
    assert_eq!(scene.object_name(1), "ball");
    assert_eq!(scene.num_objects(), 2);
    assert_eq!(scene.object_index("nothing"), None);
    assert_eq!(scene.in_contact("cube", "nothing"), None);
    scene.restore_home(&PhysicalParams::default(), &[]).unwrap();
    assert!(scene.object_parked(0) && scene.object_parked(1));
    let nan = Isometry3::from_parts(
        Translation3::new(f64::NAN, 0.0, 0.0),
        UnitQuaternion::identity(),
    );
    assert!(scene.set_object_pose(0, &nan).is_err());
}

#[test]
fn bad_object_and_bin_settings_name_their_key() {
    type Mutation = fn(&mut SceneConfig);
    let cases: Vec<(&str, &str, Mutation)> = vec![
        ("objects", "1 to 16", |c| c.objects.clear()),
        ("objects", "1 to 16", |c| {
            c.objects = (0..17)
                .map(|i| object(&format!("o{i}"), box_of([0.03; 3])))
                .collect()
        }),
        ("objects[1].shape.radius", "positive", |c| {
            c.objects
                .push(object("ball", ObjectShape::Sphere { radius: -0.02 }))
        }),
        ("objects[0].shape.height", "positive", |c| {
            c.objects[0].shape = ObjectShape::Cylinder {
                radius: 0.02,
                height: 0.0,
            }
        }),
        ("objects[0].shape.size[2]", "positive", |c| {
            c.objects[0].shape = box_of([0.05, 0.05, f32::NAN])
        }),
        ("objects[0].shape", "90 mm gripper opening", |c| {
            c.objects[0].shape = box_of([0.1, 0.09, 0.05])
        }),
        ("objects[0].shape", "90 mm gripper opening", |c| {
            c.objects[0].shape = ObjectShape::Cylinder {
                radius: 0.05,
                height: 0.05,
            }
        }),
        ("objects[0].mass", "positive", |c| c.objects[0].mass = 0.0),
        ("objects[0].friction", "positive", |c| {
            c.objects[0].friction = -1.0
        }),
        ("objects[0].angular_damping", "non-negative", |c| {
            c.objects[0].angular_damping = f32::NAN
        }),
        ("placement.clearance", "[0, 0.2]", |c| {
            c.placement.clearance = -0.01
        }),
        ("objects[0].color", "0..=1", |c| {
            c.objects[0].color = [2.0, 0.0, 0.0]
        }),
        ("objects[0].shape.scale", "positive", |c| {
            c.objects[0].shape = ObjectShape::Mesh {
                path: "x.stl".into(),
                scale: 0.0,
            }
        }),
        ("objects[1].name", "already", |c| {
            c.objects
                .push(object("cube", ObjectShape::Sphere { radius: 0.02 }))
        }),
        ("objects[0].name", "table", |c| {
            c.objects[0].name = "table".into()
        }),
        ("objects[0].name", "empty", |c| {
            c.objects[0].name = " ".into()
        }),
        ("bins[0].name", "already", |c| {
            c.bins.push(BinConfig {
                name: "cube".into(),
                ..BinConfig::default()
            })
        }),
        ("bins[0].inner_size[1]", "positive", |c| {
            c.bins.push(BinConfig {
                inner_size: [0.1, -0.1],
                ..BinConfig::default()
            })
        }),
        ("bins[0].wall_height", "wall_thickness", |c| {
            c.bins.push(BinConfig {
                wall_height: 0.01,
                wall_thickness: 0.02,
                ..BinConfig::default()
            })
        }),
        ("bins[0].center", "overhangs", |c| {
            c.bins.push(BinConfig {
                center: [1.0, 0.0],
                ..BinConfig::default()
            })
        }),
    ];
    for (key, problem, mutate) in cases {
        let mut config = SceneConfig::default();
        mutate(&mut config);
        let err = config
            .validate()
            .err()
            .unwrap_or_else(|| panic!("{key}: accepted"))
            .to_string();
        assert!(err.contains(key) && err.contains(problem), "{key}: {err}");
        // The scene refuses it too.
        assert!(Scene::new(config).is_err());
    }

    // Checks that need the robot or the mesh file happen when the scene is built.
    let built: Vec<(&str, &str, Mutation)> = vec![
        ("objects[0].name", "robot link", |c| {
            c.objects[0].name = "left_finger".into()
        }),
        ("bins[0].name", "robot link", |c| {
            c.bins.push(BinConfig {
                name: "tcp".into(),
                ..BinConfig::default()
            })
        }),
        ("objects[0].shape.path", "missing.obj", |c| {
            c.objects[0].shape = ObjectShape::Mesh {
                path: data("missing.obj"),
                scale: 1.0,
            }
        }),
        ("objects[0].shape", "90 mm gripper opening", |c| {
            c.objects[0].shape = ObjectShape::Mesh {
                path: data("frustum.stl"),
                scale: 0.003,
            }
        }),
    ];
    for (key, problem, mutate) in built {
        let mut config = SceneConfig::default();
        mutate(&mut config);
        config.validate().unwrap();
        let err = Scene::new(config)
            .err()
            .unwrap_or_else(|| panic!("{key}: accepted"))
            .to_string();
        assert!(err.contains(key) && err.contains(problem), "{key}: {err}");
    }
}

#[test]
fn objects_and_bins_read_from_toml() {
    let text = format!(
        r#"
        [[objects]]
        name = "cube"
        shape = {{ kind = "box", size = [0.05, 0.05, 0.05] }}

        [[objects]]
        name = "can"
        shape = {{ kind = "cylinder", radius = 0.02, height = 0.06 }}
        mass = 0.2
        friction = 0.5
        color = [0.1, 0.2, 0.9]

        [[objects]]
        name = "ball"
        shape = {{ kind = "sphere", radius = 0.025 }}

        [[objects]]
        name = "nut"
        shape = {{ kind = "mesh", path = "{}", scale = 0.001 }}

        [[bins]]
        name = "tray"
        center = [0.4, 0.3]
        "#,
        data("hex_prism.obj").display()
    );
    let config: SceneConfig = toml::from_str(&text).unwrap();
    config.validate().unwrap();
    assert_eq!(config.objects[0], ObjectConfig::default());
    assert_eq!(
        config.objects[1],
        ObjectConfig {
            name: "can".into(),
            shape: ObjectShape::Cylinder {
                radius: 0.02,
                height: 0.06
            },
            mass: 0.2,
            friction: 0.5,
            color: [0.1, 0.2, 0.9],
            angular_damping: 0.0,
        }
    );
    assert_eq!(config.objects[3].shape, hex_prism());
    assert_eq!(
        config.bins,
        vec![BinConfig {
            name: "tray".into(),
            center: [0.4, 0.3],
            ..BinConfig::default()
        }]
    );
    let scene = Scene::new(config).unwrap();
    assert_eq!(scene.num_objects(), 4);
    assert_eq!(scene.object_index("nut"), Some(3));

    // No `objects` key: the default cube.
    let config: SceneConfig = toml::from_str("[table]\nheight = 0.7\n").unwrap();
    assert_eq!(config.objects, vec![ObjectConfig::default()]);

    for (bad, key) in [
        (
            "[[objects]]\nname = \"a\"\nshape = { kind = \"sphere\", radius = 0.02, height = 1.0 }\n",
            "height",
        ),
        (
            "[[objects]]\nname = \"a\"\nshape = { kind = \"cone\", radius = 0.02 }\n",
            "cone",
        ),
        (
            "[[objects]]\nname = \"a\"\nshape = { kind = \"sphere\", radius = 0.02 }\nsize = 1\n",
            "size",
        ),
        (
            "[[objects]]\nshape = { kind = \"sphere\", radius = 0.02 }\n",
            "name",
        ),
        ("[[bins]]\nheight = 0.1\n", "height"),
    ] {
        let err = toml::from_str::<SceneConfig>(bad).unwrap_err().to_string();
        assert!(err.contains(key), "{bad}: {err}");
    }
}

#[test]
fn environment_shapes_list_the_table_placed_objects_and_bin_parts_where_they_are() {
    use fairgrasp_sim::scene::ShapeOwner;
    let mut scene = scene_with(
        vec![
            object("a", box_of([0.04, 0.04, 0.04])),
            object("b", ObjectShape::Sphere { radius: 0.02 }),
        ],
        vec![BinConfig::default()],
    );
    scene.restore_home(&PhysicalParams::default(), &[]).unwrap();
    let z = scene.table_top() as f64 + 0.02;
    let pose = at(&scene, 0.5, -0.1, z);
    scene.set_object_pose(1, &pose).unwrap();
    let shapes = scene.environment_shapes();
    let owners: Vec<ShapeOwner> = shapes.iter().map(|s| s.owner).collect();
    // Object 0 is parked: left out. A bin is a floor and four walls.
    assert_eq!(
        owners,
        [
            ShapeOwner::Table,
            ShapeOwner::Object(1),
            ShapeOwner::Bin(0),
            ShapeOwner::Bin(0),
            ShapeOwner::Bin(0),
            ShapeOwner::Bin(0),
            ShapeOwner::Bin(0),
        ]
    );
    // The teleported sphere is where it was put, before any step moved its collider.
    let sphere = &shapes[1];
    assert!(sphere.shape.as_ball().is_some());
    let t = sphere.pose.translation;
    assert!((t - to_pose(&pose).translation).length() < 1e-5, "{t}");
    // The table's top face is at the table height.
    let table = &shapes[0];
    let aabb = table.shape.compute_aabb(&table.pose);
    assert!((aabb.maxs.z - scene.table_top()).abs() < 1e-5);
}
