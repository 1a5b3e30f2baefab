//! A saved model, loaded as a `Policy`, acts exactly as the learner it was saved from; models
//! written before format 2 still load and act as their weights say.

use fairgrasp_env::tasks::classic::{Pendulum, PointReach};
use fairgrasp_env::wrappers::{RescaleAction, VecNormalize, VecNormalizeConfig};
use fairgrasp_env::{Env, VecEnv, VectorEnv};
use fairgrasp_rl::algorithm::{Algorithm, TensorMap};
use fairgrasp_rl::model::{FORMAT_VERSION, ModelMeta, load_tensors, save_model};
use fairgrasp_rl::ppo::{Ppo, PpoConfig};
use fairgrasp_rl::sac::{Sac, SacConfig};
use fairgrasp_rl::td3::{Td3, Td3Config};
use fairgrasp_rl::{AlgoConfig, Policy};
use std::path::Path;

/// `model.json` for a learner trained on a classic task with observation normalisation.
fn meta<V: VectorEnv>(
    algo: AlgoConfig,
    venv: &VecNormalize<V>,
    env_id: &str,
    steps: u64,
) -> ModelMeta {
    ModelMeta {
        format_version: FORMAT_VERSION,
        algo,
        obs_dim: venv.obs_dim(),
        act_dim: venv.act_dim(),
        env_id: env_id.into(),
        env: serde_json::json!({ "max_steps": 50 }),
        normalization: Some(venv.state().to_json()),
        num_timesteps: steps,
        train_seed: 1,
        n_envs: venv.num_envs(),
        privileged_dim: 0,
        pixel_actor: None,
    }
}

/// Raw observations of fresh episodes and of the training environments now.
fn raw_observations<E: Env, V: VectorEnv>(mut env: E, venv: &VecNormalize<V>) -> Vec<Vec<f32>> {
    let mut out: Vec<Vec<f32>> = (0..6)
        .map(|seed| env.reset(Some(500 + seed)).unwrap().0)
        .collect();
    let dim = venv.obs_dim();
    out.extend(
        venv.original_observations()
            .chunks(dim)
            .map(<[f32]>::to_vec),
    );
    out
}

/// Loads the model saved in `dir` and checks its deterministic actions against `predict` of
/// the learner on the normalised observations, bit for bit.
fn assert_policy_matches<A: Algorithm, V: VectorEnv>(
    dir: &Path,
    algo: &mut A,
    venv: &VecNormalize<V>,
    observations: &[Vec<f32>],
) {
    let mut policy = Policy::load(dir).unwrap();
    for raw in observations {
        let normalized = venv.normalize_obs(raw).unwrap();
        // Otherwise the check would not show that the policy normalises as the learner did.
        assert_ne!(&normalized, raw);
        let want = algo.predict(&normalized, true).unwrap();
        assert_eq!(policy.act(raw, true).unwrap(), want);
    }
    let batch: Vec<f32> = observations.concat();
    let actions = policy.act_batch(&batch, true).unwrap();
    assert_eq!(actions.len(), observations.len() * policy.act_dim());
}

#[test]
fn a_loaded_ppo_policy_acts_exactly_as_its_learner() {
    let n_envs = 4;
    let envs = (0..n_envs).map(|_| PointReach::new()).collect();
    let mut venv =
        VecNormalize::new(VecEnv::new(envs, 1).unwrap(), VecNormalizeConfig::default()).unwrap();
    venv.reset(Some(1)).unwrap();
    let config = PpoConfig {
        n_steps: 64,
        batch_size: 128,
        n_epochs: 2,
        net_arch: vec![16, 16],
        ..PpoConfig::default()
    };
    let mut ppo = Ppo::new(config.clone(), 6, 2, n_envs, 3).unwrap();
    for _ in 0..3 {
        ppo.learn_iteration(&mut venv, 1.0, &mut |_| {}).unwrap();
    }
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model");
    let meta = meta(
        AlgoConfig::Ppo(config),
        &venv,
        "PointReach-v0",
        ppo.num_timesteps,
    );
    save_model(&model, &ppo.weights().unwrap(), &meta).unwrap();

    let observations = raw_observations(PointReach::new(), &venv);
    assert_policy_matches(&model, &mut ppo, &venv, &observations);

    let mut policy = Policy::load(&model).unwrap();
    assert_eq!(
        (policy.env_id(), policy.obs_dim(), policy.act_dim()),
        ("PointReach-v0", 6, 2)
    );
    assert_eq!(policy.env_config()["max_steps"], 50);
    assert_eq!(policy.meta().num_timesteps, ppo.num_timesteps);
    // Stochastic actions come from the policy's own stream: seeded 0 on loading, reset by
    // `set_seed`.
    let obs = &observations[0];
    let first = policy.act(obs, false).unwrap();
    assert_ne!(first, policy.act(obs, false).unwrap());
    assert_ne!(first, policy.act(obs, true).unwrap());
    assert_eq!(
        Policy::load(&model).unwrap().act(obs, false).unwrap(),
        first
    );
    policy.set_seed(0);
    assert_eq!(policy.act(obs, false).unwrap(), first);
    policy.set_seed(1);
    assert_ne!(policy.act(obs, false).unwrap(), first);
}

#[test]
fn a_loaded_sac_policy_acts_exactly_as_its_learner() {
    let n_envs = 2;
    let envs = (0..n_envs)
        .map(|_| RescaleAction::new(Pendulum::new()).unwrap())
        .collect();
    let mut venv =
        VecNormalize::new(VecEnv::new(envs, 1).unwrap(), VecNormalizeConfig::default()).unwrap();
    venv.reset(Some(1)).unwrap();
    let config = SacConfig {
        buffer_size: 1_000,
        learning_starts: 64,
        batch_size: 32,
        net_arch: vec![16, 16],
        ..SacConfig::default()
    };
    let mut sac = Sac::new(config.clone(), 3, 1, n_envs, 3).unwrap();
    for _ in 0..64 {
        sac.learn_iteration(&mut venv, 1.0, &mut |_| {}).unwrap();
    }
    assert!(sac.n_updates() > 0);
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model");
    let meta = meta(
        AlgoConfig::Sac(config),
        &venv,
        "Pendulum-v1",
        sac.num_timesteps(),
    );
    save_model(&model, &sac.weights().unwrap(), &meta).unwrap();

    let env = RescaleAction::new(Pendulum::new()).unwrap();
    let observations = raw_observations(env, &venv);
    assert_policy_matches(&model, &mut sac, &venv, &observations);

    // Stochastic actions lie in the squashed box and differ from the mode.
    let mut policy = Policy::load(&model).unwrap();
    let obs = &observations[0];
    let sample = policy.act(obs, false).unwrap();
    assert!(sample.iter().all(|a| (-1.0..=1.0).contains(a)));
    assert_ne!(sample, policy.act(obs, true).unwrap());
}

#[test]
fn a_loaded_td3_policy_acts_exactly_as_its_learner() {
    let n_envs = 2;
    let envs = (0..n_envs)
        .map(|_| RescaleAction::new(Pendulum::new()).unwrap())
        .collect();
    let mut venv =
        VecNormalize::new(VecEnv::new(envs, 1).unwrap(), VecNormalizeConfig::default()).unwrap();
    venv.reset(Some(1)).unwrap();
    let config = Td3Config {
        buffer_size: 1_000,
        learning_starts: 64,
        batch_size: 32,
        net_arch: vec![16, 16],
        ..Td3Config::default()
    };
    let mut td3 = Td3::new(config.clone(), 3, 1, n_envs, 3).unwrap();
    for _ in 0..64 {
        td3.learn_iteration(&mut venv, 1.0, &mut |_| {}).unwrap();
    }
    assert!(td3.n_updates() > 1);
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model");
    let meta = meta(
        AlgoConfig::Td3(config),
        &venv,
        "Pendulum-v1",
        td3.num_timesteps(),
    );
    save_model(&model, &td3.weights().unwrap(), &meta).unwrap();

    let env = RescaleAction::new(Pendulum::new()).unwrap();
    let observations = raw_observations(env, &venv);
    assert_policy_matches(&model, &mut td3, &venv, &observations);

    // Deterministic actions repeat; exploration noise moves them, within [-1, 1].
    let mut policy = Policy::load(&model).unwrap();
    let obs = &observations[0];
    let mode = policy.act(obs, true).unwrap();
    assert_eq!(mode, policy.act(obs, true).unwrap());
    let sample = policy.act(obs, false).unwrap();
    assert!(sample.iter().all(|a| (-1.0..=1.0).contains(a)));
    assert_ne!(sample, mode);
    // Only the acting network is exported.
    let names: Vec<String> = policy.actor_tensors().into_keys().collect();
    assert!(names.iter().all(|n| n.starts_with("actor.")), "{names:?}");
}

#[test]
fn errors_name_the_model_and_the_problem() {
    let envs = vec![PointReach::new()];
    let mut venv =
        VecNormalize::new(VecEnv::new(envs, 1).unwrap(), VecNormalizeConfig::default()).unwrap();
    venv.reset(Some(0)).unwrap();
    let config = PpoConfig {
        net_arch: vec![4],
        ..PpoConfig::default()
    };
    let ppo = Ppo::new(config.clone(), 6, 2, 1, 0).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model");
    let meta = meta(AlgoConfig::Ppo(config), &venv, "PointReach-v0", 0);
    save_model(&model, &ppo.weights().unwrap(), &meta).unwrap();
    let mut policy = Policy::load(&model).unwrap();
    let name = model.display().to_string();

    for (obs, problem) in [
        (vec![0.0; 5], "observation has 5 values, the model takes 6"),
        (vec![0.0, 1.0, f32::NAN, 0.0, 0.0, 0.0], "value 2 is NaN"),
        (vec![f32::INFINITY; 6], "value 0 is inf"),
    ] {
        let err = policy.act(&obs, true).unwrap_err().to_string();
        assert!(err.contains(&name) && err.contains(problem), "{err}");
    }
    let mut batch = vec![0.0; 12];
    batch[7] = f32::NEG_INFINITY;
    let err = policy.act_batch(&batch, true).unwrap_err().to_string();
    assert!(err.contains("observation 1, value 1 is -inf"), "{err}");
    let err = policy.act_batch(&batch[..7], true).unwrap_err().to_string();
    assert!(err.contains("7 observation values"), "{err}");

    // Weights that do not fit model.json: each error names the file and the tensor.
    let weights = ppo.weights().unwrap();
    let mut missing = weights.clone();
    missing.remove("log_std");
    let mut misshaped = weights.clone();
    let zeros =
        candle_core::Tensor::zeros((2, 4), candle_core::DType::F32, &candle_core::Device::Cpu);
    misshaped.insert("vf.l1.weight".into(), zeros.unwrap());
    let mut extra = weights.clone();
    extra.insert("pi.l9.bias".into(), weights["log_std"].clone());
    for (problem, broken) in [
        ("the weights lack tensor `log_std`", missing),
        ("tensor `vf.l1.weight` has shape [2, 4]", misshaped),
        (
            "tensor `pi.l9.bias`, which this network does not have",
            extra,
        ),
    ] {
        let target = dir.path().join("broken");
        save_model(&target, &broken, &meta).unwrap();
        let err = Policy::load(&target).err().unwrap().to_string();
        assert!(
            err.contains(&target.display().to_string())
                && err.contains("model.safetensors")
                && err.contains(problem),
            "{err}"
        );
    }

    // Statistics for other observations, an unknown algorithm, missing settings.
    let other_stats = {
        let mut venv = VecNormalize::new(
            VecEnv::new(vec![Pendulum::new()], 1).unwrap(),
            VecNormalizeConfig::default(),
        )
        .unwrap();
        venv.reset(Some(0)).unwrap();
        venv.state().to_json()
    };
    let metas: Vec<(ModelMeta, &str)> = vec![
        (
            ModelMeta {
                normalization: Some(other_stats),
                ..meta.clone()
            },
            "normalisation statistics for 3 values, the model takes 6",
        ),
        (
            ModelMeta {
                normalization: Some("{}".into()),
                ..meta.clone()
            },
            "normalisation statistics: not a valid",
        ),
    ];
    for (bad, problem) in metas {
        let target = dir.path().join("bad_meta");
        save_model(&target, &weights, &bad).unwrap();
        let err = Policy::load(&target).err().unwrap().to_string();
        assert!(err.contains("model.json") && err.contains(problem), "{err}");
    }
    // An algorithm this build does not know, or one without its settings.
    type Edit = fn(&mut serde_json::Value);
    let edits: [(Edit, &str); 2] = [
        (|m| m["algo"] = "dqn".into(), "unknown variant `dqn`"),
        (
            |m| {
                m.as_object_mut().unwrap().remove("ppo");
            },
            "names algorithm ppo but has no `ppo` settings",
        ),
    ];
    for (edit, problem) in edits {
        let target = dir.path().join("bad_meta");
        save_model(&target, &weights, &meta).unwrap();
        let path = target.join("model.json");
        let mut json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        edit(&mut json);
        std::fs::write(&path, json.to_string()).unwrap();
        let err = Policy::load(&target).err().unwrap().to_string();
        assert!(err.contains("model.json") && err.contains(problem), "{err}");
    }
}

/// `x ↦ W x + b` for the layer `name` of `weights`.
fn linear(weights: &TensorMap, name: &str, x: &[f64]) -> Vec<f64> {
    let w = weights[&format!("{name}.weight")].to_vec2::<f32>().unwrap();
    let b = weights[&format!("{name}.bias")].to_vec1::<f32>().unwrap();
    w.iter()
        .zip(&b)
        .map(|(row, &b)| row.iter().zip(x).map(|(&w, &x)| w as f64 * x).sum::<f64>() + b as f64)
        .collect()
}

/// The MLP `{prefix}l0, l1, …` of `weights` applied to `x`, by hand.
fn mlp(weights: &TensorMap, prefix: &str, x: &[f64], activation: fn(f64) -> f64) -> Vec<f64> {
    let layers = (0..)
        .take_while(|i| weights.contains_key(&format!("{prefix}l{i}.weight")))
        .count();
    assert!(layers >= 2, "no MLP under `{prefix}`");
    let mut x = x.to_vec();
    for i in 0..layers {
        x = linear(weights, &format!("{prefix}l{i}"), &x);
        if i + 1 < layers {
            x.iter_mut().for_each(|v| *v = activation(*v));
        }
    }
    x
}

/// Models written by the last format-1 build (`fairgrasp train` of tiny PPO and SAC networks on
/// the grasp task, both with observation normalisation) load, and act as their weights say: the
/// tensors keep their names and meanings.
#[test]
fn models_saved_in_format_1_load_and_act_as_their_weights_say() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/format1");
    for algo in ["ppo", "sac"] {
        let dir = data.join(algo);
        let mut policy = Policy::load(&dir).unwrap();
        assert_eq!(policy.meta().algo.algo().as_str(), algo);
        assert_eq!(policy.meta().format_version, FORMAT_VERSION);
        assert_eq!(policy.env_id(), "FaArmGrasp-v0");
        assert!(policy.env_config()["task"].is_object());
        // Its settings, upgraded, build the environment it was trained on.
        let table = fairgrasp_rl::model::env_table(policy.env_config()).unwrap();
        let env = fairgrasp_env::registry::make(policy.env_id(), &table).unwrap();
        assert_eq!(env.observation_space().dim(), policy.obs_dim());
        assert_eq!(env.action_space().dim(), policy.act_dim());
        let weights = load_tensors(&dir.join("model.safetensors")).unwrap();
        let stats = policy
            .meta()
            .normalization
            .as_deref()
            .map(|json| fairgrasp_env::wrappers::VecNormalizeState::from_json(json).unwrap());
        let stats = stats.expect("the fixtures were trained with normalisation");
        for k in 0..5 {
            let obs: Vec<f32> = (0..policy.obs_dim())
                .map(|i| ((i * 7 + k * 13) as f32 * 0.37).sin() * (1.0 + k as f32))
                .collect();
            let x: Vec<f64> = stats
                .normalize_obs(&obs)
                .unwrap()
                .iter()
                .map(|&v| v as f64)
                .collect();
            let want: Vec<f64> = if algo == "ppo" {
                mlp(&weights, "pi.", &x, f64::tanh)
            } else {
                let out = mlp(&weights, "actor.", &x, |v| v.max(0.0));
                out[..policy.act_dim()].iter().map(|m| m.tanh()).collect()
            };
            let got = policy.act(&obs, true).unwrap();
            assert_eq!(got.len(), want.len());
            for (g, w) in got.iter().zip(&want) {
                assert!((*g as f64 - w).abs() < 1e-5, "{algo}: {got:?} vs {want:?}");
            }
        }
    }
}

/// A camera policy saved as a model (`pixel_actor` in `model.json`) loads and acts on the
/// observations of its environment exactly as the network it was saved from; its errors name
/// what is missing.
#[test]
fn a_loaded_camera_policy_acts_on_state_and_images_as_its_network() {
    use fairgrasp_env::{GraspConfig, GraspEnv, ObsMode};
    use fairgrasp_rl::model::PixelActorMeta;
    use fairgrasp_rl::policies::pixel_actor::{PixelActor, PixelActorConfig, PixelCache};
    use rand::SeedableRng;

    let mut config = GraspConfig::default();
    config.camera.mode = ObsMode::RgbState;
    (config.camera.width, config.camera.height) = (24, 24);
    let mut env = GraspEnv::new(config.clone()).unwrap();
    let images = env.image_space().unwrap().clone();
    let (state_dim, act_dim) = (env.observation_space().dim(), env.action_space().dim());
    let actor_config = PixelActorConfig {
        features: 8,
        net_arch: vec![16],
        ..PixelActorConfig::default()
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
    let mut actor = PixelActor::new(&actor_config, &images, state_dim, act_dim, &mut rng).unwrap();
    let (obs, _) = env.reset(Some(4)).unwrap();
    actor.fit_state_scale(
        &[obs.clone(), obs.iter().map(|v| v + 0.5).collect()].concat(),
        1e-3,
    );
    let meta = ModelMeta {
        format_version: FORMAT_VERSION,
        algo: AlgoConfig::default(),
        obs_dim: state_dim,
        act_dim,
        env_id: "FaArmGrasp-v0".into(),
        env: serde_json::to_value(&config).unwrap(),
        normalization: None,
        num_timesteps: 0,
        train_seed: 0,
        n_envs: 1,
        privileged_dim: 0,
        pixel_actor: Some(PixelActorMeta {
            actor: actor_config,
            images: images.clone(),
        }),
    };
    let dir = tempfile::tempdir().unwrap();
    save_model(dir.path(), &actor.weights(), &meta).unwrap();
    let mut policy = Policy::load(dir.path()).unwrap();
    assert_eq!(policy.image_space(), Some(&images));

    let mut cache = PixelCache::default();
    let (mut obs, _) = env.reset(Some(5)).unwrap();
    for step in 0..5 {
        let image = env.image().unwrap().to_vec();
        let want = actor.forward(&obs, &image, 1, &mut cache).unwrap();
        let got = policy.act_with_images(&obs, Some(&image), true).unwrap();
        assert_eq!(got, want, "step {step}");
        obs = env.step(&got).unwrap().obs;
    }
    let err = policy.act(&obs, true).err().unwrap().to_string();
    assert!(
        err.contains("scene_rgb 24×24×3") && err.contains("act_with_images"),
        "{err}"
    );
    let err = policy
        .act_with_images(&obs, None, true)
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("none were given"), "{err}");
    let err = (policy.act_with_images(&obs, Some(&[0; 10]), true))
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("10 image bytes") && err.contains("1728 bytes"),
        "{err}"
    );

    // A camera policy's weights without the state's standardisation are refused by name.
    let mut weights = load_tensors(&dir.path().join("model.safetensors")).unwrap();
    weights.remove("state.mean");
    let err = Policy::from_parts(meta, &weights)
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("state.mean"), "{err}");
}
