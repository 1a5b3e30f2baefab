//! A camera policy through the deployment loop: it reads the camera's frames each step (fresh
//! ones: their age stays within the camera's delay and period), refuses to run without a
//! camera, and stops the arm when the frames go stale.

use fairgrasp_deploy::calibration::Calibration;
use fairgrasp_deploy::frame_source::{FrameSource, ReceivedImages};
use fairgrasp_deploy::runner::{DeployOptions, Deployment, JsonLog, ModelIo};
use fairgrasp_deploy::safety::{Fault, SafetyConfig};
use fairgrasp_deploy::twin::simulated::{SimulatedController, SimulatedSettings};
use fairgrasp_rl::Policy;
use fairgrasp_rl::model::{ModelMeta, PixelActorMeta, env_table, save_model};
use fairgrasp_rl::policies::pixel_actor::{PixelActor, PixelActorConfig};
use rand::SeedableRng;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

/// A camera policy with random weights on the deployment model's task, seeing 32×32 RGB, with
/// `extra` environment settings.
fn camera_model(dir: &Path, extra: &[&str]) {
    let teacher = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/deploy_ppo");
    let mut meta = ModelMeta::load(&teacher).unwrap();
    let mut table = env_table(&meta.env).unwrap();
    for item in [
        "camera.mode=\"rgb+state\"",
        "camera.width=32",
        "camera.height=32",
    ]
    .iter()
    .chain(extra)
    {
        fairgrasp_env::config::apply_override(&mut table, item).unwrap();
    }
    let env = fairgrasp_env::registry::make(&meta.env_id, &table).unwrap();
    let space = env.image_space().unwrap().clone();
    let config = PixelActorConfig {
        features: 8,
        net_arch: vec![16],
        ..PixelActorConfig::default()
    };
    let state_dim = env.observation_space().dim();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let actor = PixelActor::new(&config, &space, state_dim, meta.act_dim, &mut rng).unwrap();
    meta.obs_dim = state_dim;
    meta.env = serde_json::to_value(&table).unwrap();
    meta.normalization = None;
    meta.pixel_actor = Some(PixelActorMeta {
        actor: config,
        images: space,
    });
    save_model(dir, &actor.weights(), &meta).unwrap();
}

/// A frame as the loop took it: its capture stamp, the simulated time then, its pixels.
type Seen = (f64, f64, Vec<u8>);

/// Frames as the loop received them.
struct Watched {
    inner: Box<dyn FrameSource>,
    link: SimulatedController,
    seen: Arc<Mutex<Vec<Seen>>>,
}

impl FrameSource for Watched {
    fn latest(&mut self) -> fairgrasp_deploy::Result<Option<ReceivedImages>> {
        let images = self.inner.latest()?;
        if let Some(i) = &images {
            let mut seen = self.seen.lock().unwrap();
            seen.push((i.stamps[0], self.link.elapsed(), i.bytes.clone()));
        }
        Ok(images)
    }
}

fn deployment(dir: &Path, settings: SimulatedSettings) -> (Deployment, SimulatedController) {
    let policy = Policy::load(dir).unwrap();
    let io = ModelIo::for_policy(&policy).unwrap();
    let table = env_table(policy.env_config()).unwrap();
    let link = SimulatedController::new(policy.env_id(), &table, settings).unwrap();
    let options = DeployOptions {
        live: true,
        episodes: 1,
        max_steps: Some(12),
        safety: SafetyConfig {
            speed_scale: 0.5,
            ..SafetyConfig::default()
        },
        ..DeployOptions::default()
    };
    let deployment = Deployment::new(
        Box::new(link.clone()),
        policy,
        Calibration::identity(&io.limits_rad),
        options,
        JsonLog::create(None).unwrap(),
        Arc::new(AtomicBool::new(false)),
    )
    .unwrap();
    (deployment, link)
}

#[test]
fn a_camera_policy_acts_on_fresh_frames_and_stops_on_stale_ones() {
    let dir = tempfile::tempdir().unwrap();
    camera_model(dir.path(), &[]);
    let settings = SimulatedSettings::default();
    let (period, delay) = (settings.camera_period_ms, settings.camera_delay_ms);

    let (mut d, link) = deployment(dir.path(), settings.clone());
    let seen = Arc::new(Mutex::new(Vec::new()));
    d.set_camera(Box::new(Watched {
        inner: Box::new(link.frame_source().unwrap()),
        link: link.clone(),
        seen: seen.clone(),
    }));
    let report = d.run(&mut link.host(), &mut link.pose_source()).unwrap();
    assert!(report.fault.is_none(), "{:?}", report.fault);
    assert_eq!(report.episodes.len(), 1);
    let seen = seen.lock().unwrap();
    assert!(seen.len() >= 12, "a frame per step: {}", seen.len());
    for (stamp, now, _) in seen.iter() {
        let age_ms = (now - stamp) * 1000.0;
        assert!(
            age_ms >= delay - 1e-6 && age_ms <= delay + period + 1.0,
            "a frame {age_ms:.1} ms old (delay {delay}, period {period:.1})"
        );
    }
    let changed = (seen[0].2.iter().zip(&seen.last().unwrap().2))
        .filter(|(a, b)| a != b)
        .count();
    assert!(changed > 0, "the arm moved in the camera's view");

    // Without a camera the run is refused before anything moves.
    let (mut d, link) = deployment(dir.path(), settings.clone());
    let err = (d.run(&mut link.host(), &mut link.pose_source()))
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("camera feed") && err.contains("scene_rgb 32×32×3"),
        "{err}"
    );

    // A camera that delivers one frame a second: the deadline (150 ms) stops the arm.
    let late = SimulatedSettings {
        camera_period_ms: 1000.0,
        ..settings
    };
    let (mut d, link) = deployment(dir.path(), late);
    d.set_camera(Box::new(link.frame_source().unwrap()));
    let report = d.run(&mut link.host(), &mut link.pose_source()).unwrap();
    match report.fault {
        Some(Fault::StaleFrames {
            age_ms,
            deadline_ms,
        }) => assert!(
            age_ms > 150.0 && deadline_ms == 150.0,
            "{age_ms} {deadline_ms}"
        ),
        other => panic!("expected stale frames, got {other:?}"),
    }
}

/// The calibration file's camera pose against the one the policy learnt with: none given,
/// where it learnt, and moved or turned beyond the training's randomisation.
#[test]
fn the_cells_camera_pose_is_checked_against_the_models() {
    use fairgrasp_deploy::calibration::CameraPose;
    let dir = tempfile::tempdir().unwrap();
    camera_model(dir.path(), &[]);
    let policy = Policy::load(dir.path()).unwrap();
    let io = ModelIo::for_policy(&policy).unwrap();
    let mut calibration = Calibration::identity(&io.limits_rad);
    let why = io.camera_mismatch(&calibration).unwrap();
    assert!(why.contains("no [camera] pose"), "{why}");
    let scene = &io.camera.as_ref().unwrap().scene;
    let trained = CameraPose {
        eye: scene.eye.map(f64::from),
        target: scene.target.map(f64::from),
        fov_deg: scene.fov_deg as f64,
    };
    calibration.camera = Some(trained.clone());
    assert_eq!(io.camera_mismatch(&calibration), None);
    // The model learnt without visual randomisation: 5 mm and 1° are what it knows.
    let mut moved = trained.clone();
    moved.eye[1] += 0.05;
    moved.target[1] += 0.05;
    calibration.camera = Some(moved);
    let why = io.camera_mismatch(&calibration).unwrap();
    assert!(why.contains("50 mm") && !why.contains("looks"), "{why}");
    let mut turned = trained;
    turned.target[2] -= 0.1;
    turned.fov_deg += 4.0;
    calibration.camera = Some(turned);
    let why = io.camera_mismatch(&calibration).unwrap();
    assert!(
        why.contains("looks") && why.contains("field of view differs by 4.0°"),
        "{why}"
    );
    let mut bad = calibration.clone();
    bad.camera.as_mut().unwrap().fov_deg = 400.0;
    assert!(bad.validate().unwrap_err().to_string().contains("fov_deg"));
    // A state policy has no camera to check.
    let state =
        Policy::load(&PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/deploy_ppo"))
            .unwrap();
    assert_eq!(
        ModelIo::for_policy(&state)
            .unwrap()
            .camera_mismatch(&calibration),
        None
    );
}

/// The calibration file's wrist camera mounting against the model's (beside the scene
/// camera's, which keeps its own check): none given, as trained, and off in offset,
/// direction and field of view beyond the training's randomisation.
#[test]
fn the_cells_wrist_camera_mounting_is_checked_against_the_models() {
    use fairgrasp_deploy::calibration::WristCameraMount;
    let dir = tempfile::tempdir().unwrap();
    camera_model(
        dir.path(),
        &["camera.wrist.enabled=true", "camera.randomize.enabled=true"],
    );
    let policy = Policy::load(dir.path()).unwrap();
    let io = ModelIo::for_policy(&policy).unwrap();
    let mut calibration = Calibration::identity(&io.limits_rad);
    let why = io.wrist_camera_mismatch(&calibration).unwrap();
    assert!(why.contains("no [wrist_camera] mounting"), "{why}");
    let wrist = &io.camera.as_ref().unwrap().wrist;
    let trained = WristCameraMount {
        offset: wrist.offset.map(f64::from),
        direction: [0.0, 0.0, 2.0],
        fov_deg: wrist.fov_deg as f64,
    };
    calibration.wrist_camera = Some(trained.clone());
    assert_eq!(io.wrist_camera_mismatch(&calibration), None);
    // Within the training's ±2 cm and 3°: nothing to say.
    let mut near = trained.clone();
    near.offset[0] += 0.015;
    near.direction = [0.0, 0.04, 1.0];
    calibration.wrist_camera = Some(near);
    assert_eq!(io.wrist_camera_mismatch(&calibration), None);
    let mut off = trained.clone();
    off.offset[2] -= 0.03;
    off.direction = [0.1, 0.0, 1.0];
    off.fov_deg += 5.0;
    calibration.wrist_camera = Some(off);
    let why = io.wrist_camera_mismatch(&calibration).unwrap();
    assert!(
        why.contains("wrist camera")
            && why.contains("30 mm")
            && why.contains("looks 5.7°")
            && why.contains("field of view differs by 5.0°"),
        "{why}"
    );
    // Only the wrist: the scene camera's check speaks of its own pose.
    assert!(!io.camera_mismatch(&calibration).unwrap().contains("wrist"));
    let mut bad = calibration.clone();
    bad.wrist_camera.as_mut().unwrap().direction = [0.0; 3];
    let err = bad.validate().unwrap_err().to_string();
    assert!(
        err.contains("wrist_camera") && err.contains("direction"),
        "{err}"
    );
    bad.wrist_camera.as_mut().unwrap().direction = [0.0, 0.0, 1.0];
    bad.wrist_camera.as_mut().unwrap().offset[1] = f64::NAN;
    assert!(bad.validate().is_err());
    // A model without the wrist camera has nothing to check there.
    let scene_only = tempfile::tempdir().unwrap();
    camera_model(scene_only.path(), &[]);
    let io = ModelIo::for_policy(&Policy::load(scene_only.path()).unwrap()).unwrap();
    assert_eq!(
        io.wrist_camera_mismatch(&Calibration::identity(&io.limits_rad)),
        None
    );
}
