//! The image render modes of the arm environments (frames, the camera settings, and that
//! rendering leaves the simulation alone) and their camera observations (`[camera]`).

use fairgrasp_env::core::{Frame, RenderMode};
use fairgrasp_env::render::Segment;
use fairgrasp_env::sim::rapier3d::math::Vector;
use fairgrasp_env::{Env, EnvError, GraspConfig, GraspEnv, ObsMode, VecEnv, VectorEnv};

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

fn camera_env(mutate: impl FnOnce(&mut GraspConfig)) -> GraspEnv {
    let mut config = GraspConfig::default();
    mutate(&mut config);
    GraspEnv::new(config).unwrap()
}

fn mode_env(mode: ObsMode, wrist: bool) -> GraspEnv {
    camera_env(|c| {
        c.camera.mode = mode;
        c.camera.wrist.enabled = wrist;
    })
}

#[test]
fn a_pixel_mode_shows_the_camera_and_the_arm_and_gives_the_object_to_the_critic_only() {
    let mut state_env = mode_env(ObsMode::State, false);
    let mut env = mode_env(ObsMode::RgbState, false);
    assert!(state_env.image_space().is_none());
    let space = env.image_space().expect("rgb+state has images").clone();
    assert_eq!(space.views.len(), 1);
    let view = &space.views[0];
    assert_eq!(
        (view.name.as_str(), view.height, view.width, view.channels),
        ("scene_rgb", 64, 64, 3)
    );
    assert!(env.image().is_none(), "no images before the first reset");
    // Joints, speeds, TCP position and orientation, gripper, previous action.
    assert_eq!(env.observation_space().dim(), 6 + 6 + 3 + 6 + 1 + 7);
    assert_eq!(
        env.privileged_dim(),
        state_env.observation_space().dim() + 1
    );

    let (obs_a, info_a) = env.reset(Some(1)).unwrap();
    let image_a = env.image().unwrap().to_vec();
    let (obs_b, info_b) = env.reset(Some(2)).unwrap();
    let image_b = env.image().unwrap().to_vec();
    assert_eq!(image_a.len(), space.len());
    // The arm starts at home whatever the seed; only the camera sees where the cube went.
    assert_eq!(obs_a, obs_b);
    assert_ne!(image_a, image_b);
    // The critic's privileged state is the state mode's observation of the same episode.
    let (state_obs, _) = state_env.reset(Some(2)).unwrap();
    assert_eq!(&info_b.privileged[..state_obs.len()], &state_obs[..]);
    assert_ne!(info_a.privileged, info_b.privileged);

    // Steps keep drawing: moving the arm changes the picture and the observation.
    let mut action = vec![0.0; env.action_space().dim()];
    action[0] = 1.0;
    let mut last = image_b;
    for _ in 0..5 {
        let step = env.step(&action).unwrap();
        assert_eq!(step.info.privileged.len(), env.privileged_dim());
        let image = env.image().unwrap();
        assert_ne!(image, &last[..], "the arm moved; the image must change");
        last = image.to_vec();
    }
}

#[test]
fn the_same_seed_draws_the_same_images() {
    let run = || {
        let mut env = mode_env(ObsMode::RgbdState, true);
        env.reset(Some(7)).unwrap();
        let mut images = env.image().unwrap().to_vec();
        let action = vec![0.3; env.action_space().dim()];
        for _ in 0..3 {
            env.step(&action).unwrap();
            images.extend_from_slice(env.image().unwrap());
        }
        images
    };
    assert_eq!(run(), run());
}

#[test]
fn depth_bytes_are_metres_over_the_range_and_rgbd_is_rgb_beside_depth() {
    let images = |mode| {
        let mut env = mode_env(mode, true);
        env.reset(Some(4)).unwrap();
        (
            env.image_space().unwrap().clone(),
            env.image().unwrap().to_vec(),
        )
    };
    let (rgb_space, rgb) = images(ObsMode::RgbState);
    let (depth_space, depth) = images(ObsMode::DepthState);
    let (rgbd_space, rgbd) = images(ObsMode::RgbdState);
    let names = |s: &fairgrasp_env::spaces::ImageSpace| -> Vec<String> {
        s.views.iter().map(|v| v.name.clone()).collect()
    };
    assert_eq!(names(&rgb_space), ["scene_rgb", "wrist_rgb"]);
    assert_eq!(names(&depth_space), ["scene_depth", "wrist_depth"]);
    assert_eq!(names(&rgbd_space), ["scene_rgbd", "wrist_rgbd"]);
    assert_eq!(rgbd.len(), rgb.len() / 3 * 4);
    for (i, pixel) in rgbd.chunks_exact(4).enumerate() {
        assert_eq!(&pixel[..3], &rgb[3 * i..3 * i + 3]);
        assert_eq!(pixel[3], depth[i]);
    }
    // The scene camera's centre ray meets the table top where it crosses the table's height;
    // the depth byte is that point's distance along the optical axis over [near, far].
    let env = mode_env(ObsMode::DepthState, false);
    let config = GraspConfig::default().camera;
    let eye = Vector::from(config.scene.eye);
    let axis = (Vector::from(config.scene.target) - eye).normalize();
    let table = env.scene().table_top();
    let metres = (eye.z - table) / -axis.z;
    let expected = 255.0 * (metres - config.near) / (config.far - config.near);
    let centre = depth[32 * 64 + 32] as f32;
    assert!(
        (centre - expected).abs() <= 1.5,
        "centre depth byte {centre}, expected about {expected:.1} ({metres:.3} m)"
    );
    // The wrist camera sees the fingers and the table close by: nearer than the scene camera.
    let wrist = &depth[64 * 64..];
    let mean = |px: &[u8]| px.iter().map(|&b| b as f32).sum::<f32>() / px.len() as f32;
    assert!(mean(wrist) < mean(&depth[..64 * 64]));
}

#[test]
fn the_vector_env_batches_images_as_bytes_and_keeps_the_last_one_of_an_episode() {
    let make = || {
        camera_env(|c| {
            c.camera.mode = ObsMode::RgbState;
            c.camera.width = 32;
            c.camera.height = 32;
            c.task.max_episode_steps = 3;
        })
    };
    let mut venv = VecEnv::new(vec![make(), make()], 1).unwrap();
    let len = venv.image_space().unwrap().len();
    assert_eq!(len, 32 * 32 * 3);
    venv.reset(Some(10)).unwrap();
    assert_eq!(venv.images().len(), 2 * len);
    for e in 0..2 {
        let own = venv.env(e).unwrap().image().unwrap();
        assert_eq!(&venv.images()[e * len..(e + 1) * len], own);
    }
    assert_ne!(
        venv.images()[..len],
        venv.images()[len..],
        "different seeds"
    );
    let actions = vec![0.2; 2 * venv.act_dim()];
    for t in 1..=3 {
        let before: Vec<u8> = venv.env(0).unwrap().image().unwrap().to_vec();
        let step = venv.step(&actions).unwrap();
        assert_eq!((step.image_len, step.images.len()), (len, 2 * len));
        if t < 3 {
            assert!(step.episode_ends[0].is_none());
            assert_ne!(step.image(0), &before[..]);
        } else {
            // The episode ended: the row is the next episode's first image, the last image of
            // the finished one is kept beside its last observation.
            let end = step.episode_ends[0]
                .as_ref()
                .expect("3 steps end the episode");
            assert_eq!(end.terminal_image.len(), len);
            assert_ne!(end.terminal_image, step.image(0));
        }
    }
}

#[test]
fn camera_settings_parse_and_bad_ones_name_the_key() {
    let parse = |overrides: &[&str]| {
        let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
        GraspConfig::from_toml_str("", &overrides)
    };
    let config = parse(&["camera.mode=\"depth+state\"", "camera.width=96"]).unwrap();
    assert_eq!(
        (config.camera.mode, config.camera.width),
        (ObsMode::DepthState, 96)
    );
    assert_eq!("rgbd+state".parse::<ObsMode>(), Ok(ObsMode::RgbdState));
    assert!("rgb".parse::<ObsMode>().unwrap_err().contains("rgb+state"));
    let key = |overrides: &[&str]| match parse(overrides) {
        Err(EnvError::Config { key, .. }) => key,
        other => panic!("{overrides:?} should be a config error, got {other:?}"),
    };
    assert_eq!(key(&["camera.width=8"]), "camera.width");
    assert_eq!(key(&["camera.far=0.01"]), "camera.far");
    assert_eq!(key(&["camera.scene.fov_deg=0.0"]), "camera.scene.fov_deg");
    assert_eq!(key(&["camera.wrist.fov_deg=190.0"]), "camera.wrist.fov_deg");
    let none = [
        "camera.mode=\"rgb+state\"",
        "camera.scene.enabled=false",
        "camera.wrist.enabled=false",
    ];
    assert_eq!(key(&none), "camera.mode");
    let config = parse(&["camera.mode=\"rgb+state\"", "camera.wrist.enabled=true"]).unwrap();
    assert!(config.camera.wrist.enabled);
}

#[test]
fn visual_randomisation_changes_the_look_per_episode_not_the_physics() {
    let env = |randomize: bool| {
        camera_env(|c| {
            c.camera.mode = ObsMode::RgbState;
            c.camera.randomize.enabled = randomize;
        })
    };
    let (mut plain, mut varied) = (env(false), env(true));
    let (plain_obs, _) = plain.reset(Some(5)).unwrap();
    let (varied_obs, _) = varied.reset(Some(5)).unwrap();
    assert_eq!(
        plain_obs, varied_obs,
        "the look draws after the episode's physics"
    );
    let first = varied.image().unwrap().to_vec();
    assert_ne!(plain.image().unwrap(), &first[..]);
    varied.reset(Some(6)).unwrap();
    assert_ne!(
        varied.image().unwrap(),
        &first[..],
        "each episode its own look"
    );
    varied.reset(Some(5)).unwrap();
    assert_eq!(
        varied.image().unwrap(),
        &first[..],
        "the same seed, the same look"
    );
    // Steps keep the episode's look but draw fresh pixel noise: the images of two steps
    // differ even where nothing moved (the background's corner).
    let action = vec![0.0; varied.action_space().dim()];
    varied.step(&action).unwrap();
    let a = varied.image().unwrap()[..30].to_vec();
    varied.step(&action).unwrap();
    assert_ne!(&varied.image().unwrap()[..30], &a[..]);

    let bad = GraspConfig::from_toml_str("", &["camera.randomize.brightness=[0.0, 1.0]".into()]);
    match bad {
        Err(EnvError::Config { key, .. }) => assert_eq!(key, "camera.randomize.brightness"),
        other => panic!("expected a config error, got {other:?}"),
    }
}

/// `camera.delay_steps`: the image shown is that of so many steps before (the episode's first
/// standing for those before it), the physics untouched; a range draws the delay per episode.
#[test]
fn delayed_images_are_those_of_earlier_steps() {
    let images = |delay: [u32; 2], seed: u64| {
        let mut env = camera_env(|c| {
            c.camera.mode = ObsMode::RgbState;
            (c.camera.width, c.camera.height) = (32, 32);
            c.camera.delay_steps = delay;
        });
        let mut out = Vec::new();
        let mut obs = Vec::new();
        for episode in 0..2 {
            env.reset(Some(seed + episode)).unwrap();
            out.push(env.image().unwrap().to_vec());
            for k in 0..6 {
                let a = [
                    0.8,
                    -0.5,
                    -0.6,
                    0.3,
                    0.2,
                    -0.4,
                    if k < 3 { 1.0 } else { -1.0 },
                ];
                let step = env.step(&a).unwrap();
                out.push(env.image().unwrap().to_vec());
                obs.push(step.obs);
            }
        }
        (out, obs)
    };
    let (now, obs) = images([0, 0], 7);
    let (late, late_obs) = images([2, 2], 7);
    assert_eq!(
        obs, late_obs,
        "the delay changes what is seen, not what happens"
    );
    assert_ne!(now[1], now[3], "the arm moves in view");
    for episode in 0..2 {
        let at = |k: usize| episode * 7 + k;
        assert_eq!(late[at(0)], now[at(0)]);
        assert_eq!(
            late[at(1)],
            now[at(0)],
            "the first image stands for the steps before"
        );
        for k in 2..7 {
            assert_eq!(late[at(k)], now[at(k - 2)], "episode {episode} step {k}");
        }
    }
    // A range: each episode's delay is one of its values, drawn from the seed.
    let (ranged, _) = images([0, 3], 11);
    let (again, _) = images([0, 3], 11);
    assert_eq!(ranged, again);
    let bad = GraspConfig {
        camera: fairgrasp_env::arm::camera::CameraObsConfig {
            delay_steps: [3, 1],
            ..Default::default()
        },
        ..GraspConfig::default()
    };
    let err = GraspEnv::new(bad).err().unwrap().to_string();
    assert!(err.contains("camera.delay_steps"), "{err}");
}
