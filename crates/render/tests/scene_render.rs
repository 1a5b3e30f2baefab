//! The renderer against the simulated scene: what appears where, depth, ids, determinism.

use fairgrasp_render::segment::{FIRST_LINK, Segment, TABLE};
use fairgrasp_render::{Camera, CameraConfig, Renderer, segment_name};
use fairgrasp_sim::rapier3d::math::Vector;
use fairgrasp_sim::rapier3d::na::{Isometry3, Translation3, UnitQuaternion};
use fairgrasp_sim::scene::{PhysicalParams, Scene, SceneConfig};

/// The arm at home and the 5 cm cube at (x, y) on the table, turned by `yaw`.
fn scene_with_cube(x: f64, y: f64, yaw: f64) -> Scene {
    let mut scene = Scene::new(SceneConfig::default()).unwrap();
    scene.restore_home(&PhysicalParams::default(), &[]).unwrap();
    let z = scene.table_top() as f64 + 0.025;
    let pose = Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
    );
    scene.set_object_pose(0, &pose).unwrap();
    scene
}

fn renderer(scene: &Scene, width: u32, height: u32) -> Renderer {
    Renderer::with_config(scene, CameraConfig::front_three_quarter(width, height)).unwrap()
}

fn world(v: Vector3) -> Vector {
    Vector::new(v.x as f32, v.y as f32, v.z as f32)
}
type Vector3 = fairgrasp_sim::rapier3d::na::Vector3<f64>;

fn cube_id() -> u16 {
    Segment::Object(0).id().unwrap()
}

#[test]
fn the_cube_covers_its_projected_centre_at_the_right_depth() {
    let scene = scene_with_cube(0.6, -0.25, 0.3);
    let mut r = renderer(&scene, 320, 240);
    r.render(&scene).unwrap();
    let centre = scene.object_state(0).pose.translation.vector;
    let (u, v) = r.camera().pixel_of(world(centre)).expect("cube in view");
    let i = r.index(u, v);
    assert_eq!(r.segmentation()[i], cube_id(), "at pixel ({u}, {v})");
    assert_eq!(segment_name(&scene, cube_id()), "cube");
    // The visible face lies between the centre and the centre minus the half-diagonal.
    let (_, _, z_centre) = r.camera().project(world(centre)).unwrap();
    let d = r.depth()[i];
    assert!(
        d <= z_centre && d >= z_centre - 0.0433,
        "depth {d}, centre at {z_centre}"
    );
    // The cube is red: red dominates at its centre.
    let px = &r.rgb()[3 * i..3 * i + 3];
    assert!(px[0] as u16 > 2 * px[1].max(px[2]).max(1) as u16, "{px:?}");
}

/// The segmentation ids within `radius` pixels of `(u, v)`.
fn ids_near(r: &Renderer, (u, v): (u32, u32), radius: i32) -> Vec<u16> {
    let (w, h) = (r.width() as i32, r.height() as i32);
    let mut ids = Vec::new();
    for dv in -radius..=radius {
        for du in -radius..=radius {
            let (x, y) = (u as i32 + du, v as i32 + dv);
            if x >= 0 && y >= 0 && x < w && y < h {
                ids.push(r.segmentation()[r.index(x as u32, y as u32)]);
            }
        }
    }
    ids
}

#[test]
fn the_gripper_appears_where_the_tcp_projects() {
    let scene = scene_with_cube(0.6, -0.25, 0.0);
    let mut r = renderer(&scene, 320, 240);
    r.render(&scene).unwrap();
    let tcp = scene.tcp_pose().translation.vector;
    let at = r.camera().pixel_of(world(tcp)).expect("TCP in view");
    // The TCP lies between the pads: within ~3 cm (8 px) the gripper shows.
    let gripper: Vec<u16> = ["gripper_base", "left_finger", "right_finger"]
        .iter()
        .map(|n| {
            let l = scene.robot().model.link_index(n).unwrap();
            Segment::Link(l).id().unwrap()
        })
        .collect();
    let near_tcp = ids_near(&r, at, 8);
    assert!(
        near_tcp.iter().any(|id| gripper.contains(id)),
        "no gripper pixel near the TCP at {at:?}: {near_tcp:?}"
    );
    // A table point far from the arm and the cube shows the table and no robot.
    let corner = Vector::new(0.95, 0.45, scene.table_top());
    let at = r.camera().pixel_of(corner).unwrap();
    assert_eq!(r.segmentation()[r.index(at.0, at.1)], TABLE);
    assert!(ids_near(&r, at, 8).iter().all(|&id| id < FIRST_LINK));
}

#[test]
fn turning_the_base_joint_changes_only_robot_pixels() {
    let mut scene = scene_with_cube(0.6, -0.3, 0.0);
    let mut r = renderer(&scene, 160, 120);
    r.render(&scene).unwrap();
    let (rgb0, seg0) = (r.rgb().to_vec(), r.segmentation().to_vec());
    let mut q = scene.arm_positions();
    q[0] += 0.6;
    scene.set_arm_positions(&q).unwrap();
    r.render(&scene).unwrap();
    let (rgb1, seg1) = (r.rgb(), r.segmentation());
    let mut changed = 0;
    for (i, (&before, &after)) in seg0.iter().zip(seg1).enumerate() {
        if rgb0[3 * i..3 * i + 3] != rgb1[3 * i..3 * i + 3] || before != after {
            changed += 1;
            assert!(
                before >= FIRST_LINK || after >= FIRST_LINK,
                "pixel {i} changed but shows no robot link before or after ({before} → {after})"
            );
        }
    }
    assert!(changed > 200, "only {changed} pixels changed");
    // The cube, away from the arm, did not move in the image.
    let cube = |seg: &[u16]| seg.iter().filter(|&&s| s == cube_id()).count();
    assert_eq!(cube(&seg0), cube(seg1));
    assert!(cube(&seg0) > 10);
}

#[test]
fn rendering_is_deterministic_and_colourful() {
    let scene = scene_with_cube(0.5, 0.1, 0.7);
    let mut a = renderer(&scene, 640, 480);
    a.render(&scene).unwrap();
    let mut b = renderer(&scene, 640, 480);
    b.render(&scene).unwrap();
    b.render(&scene).unwrap();
    assert_eq!(a.rgb(), b.rgb());
    assert_eq!(a.segmentation(), b.segmentation());
    assert_eq!(a.depth(), b.depth());
    assert_eq!(a.rgb().len(), 640 * 480 * 3);
    let mut colours: Vec<[u8; 3]> = a
        .rgb()
        .chunks_exact(3)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    colours.sort_unstable();
    colours.dedup();
    assert!(colours.len() > 20, "only {} colours", colours.len());
    // Table, cube, and several robot links are all in view.
    let mut ids = a.segmentation().to_vec();
    ids.sort_unstable();
    ids.dedup();
    assert!(ids.contains(&TABLE) && ids.contains(&cube_id()), "{ids:?}");
    assert!(
        ids.iter().filter(|&&i| i >= FIRST_LINK).count() >= 6,
        "{ids:?}"
    );
    // Background depth reads `far`; everything else is nearer.
    assert!(a.depth().iter().all(|&d| d > 0.0 && d <= a.camera().far()));
}

#[test]
fn a_camera_change_resizes_and_shape_changes_reuse_the_cache() {
    let mut scene = Scene::new(SceneConfig::default()).unwrap();
    let mut r = renderer(&scene, 32, 24);
    for seed in 0..5 {
        scene.reset(seed).unwrap();
        r.render(&scene).unwrap();
    }
    // The table and the one cube shape.
    assert_eq!(r.cached_shapes(), 2);
    r.set_camera(Camera::new(CameraConfig::top_down(48, 40)).unwrap());
    r.render(&scene).unwrap();
    assert_eq!(r.rgb().len(), 48 * 40 * 3);
    assert_eq!(r.depth().len(), 48 * 40);
    // From the top, the cube is in view.
    assert!(r.segmentation().contains(&cube_id()));
}

#[test]
fn the_documented_ids_hold_for_the_bundled_robot() {
    let scene = Scene::new(SceneConfig::default()).unwrap();
    for (id, name) in [
        (0, "background"),
        (1, "table"),
        (32, "cube"),
        (33, "unknown:33"),
        (64, "link:base_link"),
        (70, "link:wrist3_link"),
        (71, "link:tool0"),
        (72, "link:gripper_base"),
        (73, "link:left_finger"),
        (74, "link:right_finger"),
        (75, "link:tcp"),
    ] {
        assert_eq!(segment_name(&scene, id), name, "id {id}");
    }
}
