//! The registry: every id builds, steps and reports its own values by name; errors name the
//! unknown id or key.

use fairgrasp_env::registry::{self, default_config, effective_config, make};
use fairgrasp_env::{Env, EnvError};

fn table(text: &str) -> toml::Table {
    text.parse().unwrap()
}

#[test]
fn every_registered_env_builds_resets_and_steps_from_its_defaults() {
    for spec in registry::specs() {
        let mut env = make(spec.id, &toml::Table::new()).unwrap();
        assert_eq!(env.metadata().id, spec.id);
        let (obs, _) = env.reset(Some(3)).unwrap();
        assert_eq!(obs.len(), env.observation_space().dim(), "{}", spec.id);
        let action = vec![0.0; env.action_space().dim()];
        let step = env.step(&action).unwrap();
        assert!(step.obs.iter().all(|v| v.is_finite()), "{}", spec.id);
        if !step.info.reward_terms.is_empty() {
            assert!(
                (step.info.reward_terms.total() - step.reward).abs() < 1e-4,
                "{}: terms {:?} do not sum to {}",
                spec.id,
                step.info.reward_terms,
                step.reward
            );
        }
        // The default configuration, written out, is accepted back unchanged.
        let defaults = default_config(spec.id).unwrap();
        assert_eq!(effective_config(spec.id, &defaults).unwrap(), defaults);
    }
}

#[test]
fn the_arm_tasks_report_their_flags_by_name() {
    let expect = [
        ("FaArmGrasp-v0", vec!["grasped", "lift"]),
        (
            "FaArmPickPlace-v0",
            vec!["grasped", "object_goal_distance", "placed"],
        ),
        ("FaArmSort-v0", vec!["objects_sorted", "fraction_sorted"]),
    ];
    for (id, names) in expect {
        let mut env = make(id, &toml::Table::new()).unwrap();
        env.reset(Some(0)).unwrap();
        let step = env.step(&vec![0.0; env.action_space().dim()]).unwrap();
        for name in names {
            assert!(
                step.info.extras.get(name).is_some(),
                "{id} lacks `{name}` in {:?}",
                step.info.extras
            );
        }
    }
}

#[test]
fn unknown_ids_and_keys_are_errors_that_name_them() {
    let err = make("FaArmJuggle-v9", &toml::Table::new()).err().unwrap();
    let text = err.to_string();
    assert!(
        text.contains("FaArmJuggle-v9") && text.contains("FaArmPickPlace-v0"),
        "{text}"
    );

    let err = make("FaArmGrasp-v0", &table("[task]\nmax_episode_stepz = 3"))
        .err()
        .unwrap();
    assert!(err.to_string().contains("max_episode_stepz"), "{err}");

    // Sorting's own checks name their keys.
    for (setting, key) in [
        ("num_objects = 9", "task.num_objects"),
        ("object_clearance = -0.01", "task.object_clearance"),
        ("start_sorted_max = 3", "task.start_sorted_max"),
        ("start_above_bin = 1.5", "task.start_above_bin"),
        ("start_sorted_min = 1", "task.start_sorted_min"),
        ("curriculum_success = 2.0", "task.curriculum_success"),
    ] {
        let err = make("FaArmSort-v0", &table(&format!("[task]\n{setting}")))
            .err()
            .unwrap();
        assert!(
            matches!(&err, EnvError::Config { key: k, .. } if k == key),
            "{setting}: {err}"
        );
    }

    let err = make("Pendulum-v1", &table("g = 9.81")).err().unwrap();
    assert!(err.to_string().contains("no settings"), "{err}");
}

#[test]
fn the_same_seed_gives_the_same_episode_through_the_registry() {
    for id in ["FaArmPickPlace-v0", "FaArmSort-v0"] {
        let run = || {
            let mut env = make(id, &toml::Table::new()).unwrap();
            let (mut obs, _) = env.reset(Some(11)).unwrap();
            let n = env.action_space().dim();
            for k in 0..5 {
                let action: Vec<f32> = (0..n).map(|i| ((i + k) as f32 * 0.37).sin()).collect();
                obs.extend(env.step(&action).unwrap().obs);
            }
            obs
        };
        assert_eq!(run(), run(), "{id}");
    }
}

#[test]
fn the_registry_says_what_each_arm_task_offers_outside_training() {
    assert_eq!(
        registry::arm_ids(),
        ["FaArmGrasp-v0", "FaArmPickPlace-v0", "FaArmSort-v0"]
    );
    assert_eq!(registry::deployable_ids(), ["FaArmGrasp-v0"]);
    assert!(registry::arm_offer("Pendulum-v1").is_none());
    assert!(registry::arm_offer("NoSuchEnv-v0").is_none());
    for id in registry::arm_ids() {
        let offer = registry::arm_offer(id).unwrap();
        let mut world = (offer.world)(&toml::Table::new()).unwrap();
        world.start_episode(4).unwrap();
        let state = fairgrasp_env::ArmState::from_scene(world.scene());
        assert!(!world.evaluate(&state).success, "{id}");
        if let Some(deployment) = offer.deployment {
            let env = deployment(&toml::Table::new()).unwrap();
            assert!(env.success_judge().is_some(), "{id}");
        }
    }
    // Bad settings are the env's own errors.
    let offer = registry::arm_offer("FaArmGrasp-v0").unwrap();
    assert!((offer.world)(&table("nonsense = 1")).is_err());
}

/// The twin's world is the env's nominal world: each episode starts as the env's reset does
/// with randomisation off, random shapes included, whatever the settings' randomisation.
#[test]
fn an_arm_world_starts_its_episodes_as_the_nominal_env_resets() {
    use fairgrasp_env::GraspEnv;
    let settings = table("[shapes]\nenabled = true\n[randomization]\nenabled = true");
    let mut world = (registry::arm_offer("FaArmGrasp-v0").unwrap().world)(&settings).unwrap();
    let mut nominal = settings.clone();
    nominal.insert("randomization".into(), table("enabled = false").into());
    let mut env = GraspEnv::new(fairgrasp_env::config::from_table(nominal).unwrap()).unwrap();
    for seed in [0, 7, 11] {
        world.start_episode(seed).unwrap();
        env.reset(Some(seed)).unwrap();
        let (a, b) = (world.scene(), env.scene());
        assert_eq!(
            a.object_state(0).pose,
            b.object_state(0).pose,
            "seed {seed}"
        );
        assert_eq!(a.object_half_extents(0), b.object_half_extents(0));
        assert_eq!(a.arm_positions(), b.arm_positions());
    }
}

/// `fairgrasp env check`'s variants, each through the library's checker (the contract, seeding,
/// bad actions, a random rollout): every one of the grasp's 24 and the other arm tasks' 4 each.
#[test]
fn the_checker_passes_every_variant_of_every_arm_task() {
    use fairgrasp_env::check::{check_env, variants};
    use fairgrasp_env::config::apply_override;
    let grasp = variants(fairgrasp_env::ENV_ID);
    assert_eq!(grasp.len(), 24);
    let labels: std::collections::HashSet<&str> = grasp.iter().map(|v| v.label.as_str()).collect();
    assert_eq!(labels.len(), 24, "each variant its own");
    assert!(labels.contains(
        "randomization.enabled=true control.action_mode=\"joint\" task.observation=\"rich\" \
         reward.kind=\"hybrid\""
    ));
    for spec in registry::specs()
        .iter()
        .filter(|s| s.id.starts_with("FaArm"))
    {
        let variants = variants(spec.id);
        if spec.id != fairgrasp_env::ENV_ID {
            assert_eq!(variants.len(), 4, "{}", spec.id);
        }
        for variant in variants {
            let mut table = toml::Table::new();
            for item in &variant.overrides {
                apply_override(&mut table, item).unwrap();
            }
            let mut env = make(spec.id, &table).unwrap();
            let mut twin = make(spec.id, &table).unwrap();
            let report = check_env(&mut env, &mut twin, 300, 0);
            assert!(
                report.passed(),
                "{} {}: {:?}",
                spec.id,
                variant.label,
                report.checks
            );
            assert_eq!(report.rollout_steps, 300);
        }
    }
}
