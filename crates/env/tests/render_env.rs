//! The image render modes of the arm environments: frames, the camera settings, and that
//! rendering leaves the simulation alone.

use fairgrasp_env::core::{Frame, RenderMode};
use fairgrasp_env::render::Segment;
use fairgrasp_env::sim::rapier3d::math::Vector;
use fairgrasp_env::{Env, EnvError, GraspConfig, GraspEnv};

fn env_with(mode: Option<RenderMode>, width: u32, height: u32) -> GraspEnv {
    let mut config = GraspConfig::default();
    config.task.render_mode = mode;
    config.render.width = width;
    config.render.height = height;
    GraspEnv::new(config).unwrap()
}

#[test]
fn rgb_array_returns_the_camera_image_with_the_cube_in_it() {
    let mut env = env_with(Some(RenderMode::RgbArray), 84, 84);
    assert!(env.metadata().render_modes.contains(&RenderMode::RgbArray));
    env.reset(Some(3)).unwrap();
    let Some(Frame::Rgb {
        width,
        height,
        data,
    }) = env.render().unwrap()
    else {
        panic!("expected an RGB frame");
    };
    assert_eq!((width, height, data.len()), (84, 84, 84 * 84 * 3));
    let renderer = env.renderer().expect("built by render()");
    assert_eq!(renderer.rgb(), &data[..]);
    // The cube's centre shows the cube.
    let c = env.scene().object_state(0).pose.translation.vector;
    let at = Vector::new(c.x as f32, c.y as f32, c.z as f32);
    let (u, v) = renderer.camera().pixel_of(at).unwrap();
    let cube = Segment::Object(0).id().unwrap();
    assert_eq!(renderer.segmentation()[renderer.index(u, v)], cube);
    let first = &data[..3];
    assert!(data.chunks_exact(3).any(|p| p != first), "one colour");
}

#[test]
fn depth_array_returns_metres_and_follows_the_arm() {
    let mut env = env_with(Some(RenderMode::DepthArray), 64, 48);
    env.reset(Some(1)).unwrap();
    let Some(Frame::Depth {
        width,
        height,
        data,
    }) = env.render().unwrap()
    else {
        panic!("expected a depth frame");
    };
    assert_eq!((width, height, data.len()), (64, 48, 64 * 48));
    let far = env.config().render.far;
    assert!(data.iter().all(|&d| d > 0.1 && d <= far));
    // Some of the image is the table, 1-3 m away, some is background.
    assert!(data.iter().any(|&d| (1.0..3.0).contains(&d)));
    assert!(data.contains(&far));
    // Moving the arm moves the depth image.
    let mut action = vec![0.0; env.action_space().dim()];
    action[0] = 1.0;
    for _ in 0..5 {
        env.step(&action).unwrap();
    }
    let Some(Frame::Depth { data: after, .. }) = env.render().unwrap() else {
        panic!()
    };
    assert_ne!(data, after);
}

#[test]
fn rendering_does_not_change_the_episode() {
    let run = |mode: Option<RenderMode>| {
        let mut env = env_with(mode, 32, 24);
        let (mut obs, _) = env.reset(Some(5)).unwrap();
        let mut action = vec![0.3; env.action_space().dim()];
        action[1] = -0.5;
        for _ in 0..4 {
            env.render().unwrap();
            obs.extend(env.step(&action).unwrap().obs);
        }
        obs
    };
    let plain = run(None);
    assert_eq!(plain, run(Some(RenderMode::RgbArray)));
    assert_eq!(plain, run(Some(RenderMode::DepthArray)));
}

#[test]
fn render_settings_parse_and_bad_cameras_name_the_key() {
    let c = GraspConfig::from_toml_str(
        "[task]\nrender_mode = \"depth_array\"\n[render]\nwidth = 84\nheight = 84\n",
        &[],
    )
    .unwrap();
    assert_eq!(c.task.render_mode, Some(RenderMode::DepthArray));
    assert_eq!((c.render.width, c.render.height), (84, 84));
    for (set, key) in [
        ("render.fov_deg=0", "render.fov_deg"),
        ("render.width=0", "render.width"),
        ("render.far=0.01", "render.far"),
        ("render.target=[1.45, -0.95, 1.45]", "render.target"),
    ] {
        match GraspConfig::from_toml_str("", &[set.to_string()]) {
            Err(EnvError::Config { key: k, .. }) => assert_eq!(k, key, "{set}"),
            other => panic!("{set}: {other:?}"),
        }
    }
}

#[test]
fn the_sorting_task_shows_its_bins_and_objects() {
    use fairgrasp_env::tasks::sort::{SortConfig, SortEnv};
    let mut config = SortConfig::default();
    config.task.render_mode = Some(RenderMode::RgbArray);
    config.render.width = 160;
    config.render.height = 120;
    let mut env = SortEnv::new(config).unwrap();
    env.reset(Some(2)).unwrap();
    env.render().unwrap();
    let r = env.renderer().unwrap();
    let ids = r.segmentation();
    let scene = env.scene();
    for j in 0..scene.bins().len() {
        let id = Segment::Bin(j).id().unwrap();
        assert!(ids.contains(&id), "bin {j} not in view");
        assert_eq!(
            fairgrasp_env::render::segment_name(scene, id),
            scene.bins()[j].name
        );
    }
    let placed = (0..scene.num_objects())
        .filter(|&i| !scene.object_parked(i))
        .collect::<Vec<_>>();
    assert!(placed.len() >= 2);
    for i in placed {
        assert!(
            ids.contains(&Segment::Object(i).id().unwrap()),
            "object {i}"
        );
    }
    // Parked objects are not drawn.
    for i in (0..scene.num_objects()).filter(|&i| scene.object_parked(i)) {
        assert!(
            !ids.contains(&Segment::Object(i).id().unwrap()),
            "parked {i}"
        );
    }
}

#[test]
fn segmentation_array_labels_the_table_the_cube_and_the_arm_and_agrees_with_rgb() {
    let mut env = env_with(Some(RenderMode::SegmentationArray), 96, 72);
    assert!(
        env.metadata()
            .render_modes
            .contains(&RenderMode::SegmentationArray)
    );
    env.reset(Some(3)).unwrap();
    let Some(Frame::Segmentation {
        width,
        height,
        data,
    }) = env.render().unwrap()
    else {
        panic!("expected a segmentation frame");
    };
    assert_eq!((width, height, data.len()), (96, 72, 96 * 72));
    // Background, table, the cube (object 0) and some arm link are all in view.
    for id in [0u16, 1, 32] {
        assert!(data.contains(&id), "id {id} missing");
    }
    assert!(data.iter().any(|&id| id >= 64), "no robot link");
    // The same camera as rgb_array: the renderer's own segmentation of that frame.
    let renderer = env.renderer().expect("built by render()");
    assert_eq!(renderer.segmentation(), data.as_slice());
}
