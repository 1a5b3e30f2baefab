//! `fairgrasp robustness`: the grid runner on a tiny PPO model with random weights, the
//! settings a condition becomes, the JSON file and the errors.

use fairgrasp_deploy::robustness::{
    Axis, Condition, Grid, Nominal, RobustnessOptions, RobustnessReport, condition_table,
    evaluate_model, nominal_of,
};
use fairgrasp_env::arm::ActionMode;
use fairgrasp_env::tasks::grasp::GraspConfig;
use fairgrasp_env::{Env, GraspEnv};
use fairgrasp_rl::AlgoConfig;
use fairgrasp_rl::algorithm::Algorithm;
use fairgrasp_rl::model::{FORMAT_VERSION, ModelMeta, save_model};
use fairgrasp_rl::ppo::{Ppo, PpoConfig};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

const ENV_ID: &str = "FaArmGrasp-v0";

/// Short episodes keep the test fast.
fn env_config() -> GraspConfig {
    let mut c = GraspConfig::default();
    c.control.action_mode = ActionMode::Cartesian;
    c.task.max_episode_steps = 4;
    c
}

/// Saves a PPO model with random weights for the grasp task in `dir`.
fn tiny_model(dir: &Path) {
    let config = env_config();
    let env = GraspEnv::new(config.clone()).unwrap();
    let (obs_dim, act_dim) = (env.observation_space().dim(), env.action_space().dim());
    let ppo_config = PpoConfig {
        net_arch: vec![8],
        ..PpoConfig::default()
    };
    let ppo = Ppo::new(ppo_config.clone(), obs_dim, act_dim, 1, 3).unwrap();
    let meta = ModelMeta {
        format_version: FORMAT_VERSION,
        algo: AlgoConfig::Ppo(ppo_config),
        obs_dim,
        act_dim,
        env_id: ENV_ID.into(),
        env: serde_json::to_value(&config).unwrap(),
        normalization: None,
        num_timesteps: 0,
        train_seed: 1,
        n_envs: 1,
        privileged_dim: 0,
        pixel_actor: None,
    };
    save_model(dir, &ppo.weights().unwrap(), &meta).unwrap();
}

fn options() -> RobustnessOptions {
    RobustnessOptions {
        episodes: 2,
        seed: 2_000_000_000,
        threads: 2,
    }
}

#[test]
fn every_cell_is_evaluated_and_the_report_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model");
    tiny_model(&model);
    let grid = Grid::standard();
    let calls = AtomicUsize::new(0);
    let report = evaluate_model(&model, &grid, &options(), &|done, total| {
        calls.fetch_add(1, Ordering::Relaxed);
        assert!(done <= total && total == 19, "{done}/{total}");
    })
    .unwrap();
    // 19 distinct conditions: the nominal one sits on all five axes.
    assert_eq!(calls.load(Ordering::Relaxed), 19);
    let nominal = Nominal {
        object_mass: 0.1,
        object_friction: 0.8,
    };
    assert_eq!(report.nominal, nominal);
    let expected: Vec<(Axis, Vec<f32>)> = vec![
        (Axis::Mass, vec![0.5, 1.0, 1.5, 2.0, 3.0]),
        (Axis::Friction, vec![0.3, 0.5, 0.8, 1.0, 1.5, 2.0]),
        (Axis::Latency, vec![0.0, 1.0, 2.0, 3.0]),
        (Axis::Noise, vec![0.0, 1.0, 2.0, 5.0]),
        (Axis::JointOffset, vec![0.0, 0.25, 0.5, 1.0]),
    ];
    let rows: Vec<(Axis, f32)> = report.cells.iter().map(|c| (c.axis, c.value)).collect();
    let want: Vec<(Axis, f32)> = expected
        .iter()
        .flat_map(|(a, vs)| vs.iter().map(move |v| (*a, *v)))
        .collect();
    assert_eq!(rows, want);
    for c in &report.cells {
        assert_eq!(c.episodes, 2);
        assert!((0.0..=1.0).contains(&c.success_rate));
        assert!(c.mean_length > 0.0 && c.mean_length <= 4.0, "{c:?}");
        assert!(c.mean_return.is_finite());
    }
    // The nominal rows are one evaluation; the other conditions really change the episodes
    // (noise and latency change what the random policy sees and does).
    let base = Condition::nominal(&nominal);
    let nominal_rows: Vec<_> = report
        .cells
        .iter()
        .filter(|c| c.condition == base)
        .collect();
    assert_eq!(nominal_rows.len(), 5);
    assert!(
        nominal_rows
            .iter()
            .all(|c| c.mean_return == nominal_rows[0].mean_return)
    );
    let row = |axis, value| {
        report
            .cells
            .iter()
            .find(|c| c.axis == axis && c.value == value)
            .unwrap()
    };
    assert_ne!(
        row(Axis::Noise, 5.0).mean_return,
        nominal_rows[0].mean_return
    );
    assert_ne!(
        row(Axis::Latency, 3.0).mean_return,
        nominal_rows[0].mean_return
    );
    // Central: everything but mass ×3, friction 0.3 and 2, latency 3, noise 5 mm, offset 1°.
    let outside = report.cells.iter().filter(|c| !c.central).count();
    assert_eq!(outside, 6);
    assert!(!row(Axis::Mass, 3.0).central && row(Axis::Mass, 2.0).central);
    let central = report.central.as_ref().unwrap();
    assert_eq!(central.conditions, 13);
    assert!(central.min_success <= central.mean_success);

    let table = report.table();
    for label in [
        "object mass",
        "×1.5",
        "0.8",
        "3 steps",
        "5 mm",
        "0.25°",
        "central region",
    ] {
        assert!(table.contains(label), "{label} missing from\n{table}");
    }
    let path = dir.path().join("out").join("robustness.json");
    report.save(&path).unwrap();
    assert_eq!(RobustnessReport::load(&path).unwrap(), report);
    let leftovers: Vec<_> = std::fs::read_dir(path.parent().unwrap())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(leftovers, vec!["robustness.json"]);
}

#[test]
fn a_bad_model_directory_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no_such_model");
    let err = evaluate_model(&missing, &Grid::standard(), &options(), &|_, _| {})
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains(&missing.display().to_string()), "{err}");
    let broken = dir.path().join("broken");
    std::fs::create_dir_all(&broken).unwrap();
    std::fs::write(broken.join("model.json"), "{ not json").unwrap();
    let err = evaluate_model(&broken, &Grid::standard(), &options(), &|_, _| {})
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains(&broken.display().to_string()) && err.contains("model.json"),
        "{err}"
    );
    let err = RobustnessReport::load(&broken.join("model.json"))
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("model.json"), "{err}");
}

#[test]
fn a_condition_pins_every_range_of_the_model_environment() {
    let base: toml::Table = toml::from_str(&env_config().to_toml_string()).unwrap();
    let nominal = nominal_of(ENV_ID, &base).unwrap();
    let parse = |c: &Condition| {
        let table = condition_table(ENV_ID, &base, &nominal, c).unwrap();
        GraspConfig::from_toml_str(&toml::to_string(&table).unwrap(), &[]).unwrap()
    };
    let plain = parse(&Condition::nominal(&nominal));
    let r = &plain.randomization;
    assert!(r.enabled);
    assert_eq!(r.object_mass, [0.1, 0.1]);
    assert_eq!(r.object_friction, [0.8, 0.8]);
    assert_eq!(r.object_scale, [1.0, 1.0]);
    assert_eq!(r.joint_damping_scale, Some([1.0, 1.0]));
    assert_eq!(r.actuator_gain_scale, [1.0, 1.0]);
    assert_eq!((r.min_latency_steps, r.max_latency_steps), (0, 0));
    assert_eq!((r.initial_joint_jitter, r.joint_offset), (0.0, 0.0));
    assert_eq!(r.observation_noise.ee_position, 0.0);
    // Only the randomisation changes.
    let mut back = plain.clone();
    back.randomization = env_config().randomization;
    assert_eq!(back, env_config());

    let hard = Condition::nominal(&nominal)
        .with(Axis::Mass, 2.0)
        .with(Axis::Latency, 3.0)
        .with(Axis::Noise, 2.0)
        .with(Axis::JointOffset, 0.5);
    let r = parse(&hard).randomization;
    assert_eq!(r.object_mass, [0.2, 0.2]);
    assert_eq!((r.min_latency_steps, r.max_latency_steps), (3, 3));
    let n = &r.observation_noise;
    assert_eq!((n.ee_position, n.object_position), (0.002, 0.002));
    assert_eq!((n.joint_position, n.object_orientation), (0.0, 0.0));
    assert!((r.joint_offset - 0.5f32.to_radians()).abs() < 1e-9);
}

#[test]
fn tasks_without_randomisation_are_refused() {
    let err = nominal_of("PointReach-v0", &toml::Table::new())
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("PointReach-v0") && err.contains("randomization"),
        "{err}"
    );
}

#[test]
fn a_noise_condition_perturbs_positions_only_by_about_its_sigma() {
    let base: toml::Table = toml::from_str(&env_config().to_toml_string()).unwrap();
    let nominal = nominal_of(ENV_ID, &base).unwrap();
    let first_obs = |c: &Condition| {
        let table = condition_table(ENV_ID, &base, &nominal, c).unwrap();
        let mut env = fairgrasp_env::registry::make(ENV_ID, &table).unwrap();
        env.reset(Some(7)).unwrap().0
    };
    let exact = first_obs(&Condition::nominal(&nominal));
    let noisy = first_obs(&Condition::nominal(&nominal).with(Axis::Noise, 5.0));
    // `rich` layout: joints 0..12 (angles, velocities), TCP position 12..15, orientation
    // 15..21, object position 21..24, yaw features 24..26, TCP→object 26..29, lift 29.
    assert_eq!(&noisy[..12], &exact[..12]);
    assert_eq!(&noisy[15..21], &exact[15..21]);
    let diffs: Vec<f32> = [12..15, 21..24, 26..30]
        .into_iter()
        .flatten()
        .map(|i| noisy[i] - exact[i])
        .collect();
    let rms = (diffs.iter().map(|d| d * d).sum::<f32>() / diffs.len() as f32).sqrt();
    assert!(rms > 0.002 && rms < 0.010, "rms {rms} from {diffs:?}");
}
