//! `fairgrasp export`: the ONNX graph, run by a real runtime (tract), gives the actions of our
//! own inference; the safetensors file holds the whole deterministic policy.

use candle_core::{Device, Tensor};
use fairgrasp_deploy::export::onnx::{OUTPUT_ACTION, OUTPUT_ENV_ACTION};
use fairgrasp_deploy::export::{Format, export, export_policy};
use fairgrasp_env::random::standard_normal;
use fairgrasp_env::wrappers::{RescaleAction, VecNormalizeConfig, VecNormalizeState};
use fairgrasp_env::{Env, RunningMeanStd, registry};
use fairgrasp_rl::AlgoConfig;
use fairgrasp_rl::Policy;
use fairgrasp_rl::algorithm::{Algorithm, TensorMap};
use fairgrasp_rl::model::{FORMAT_VERSION, ModelMeta, env_table, save_model};
use fairgrasp_rl::nn::Activation;
use fairgrasp_rl::ppo::{Ppo, PpoConfig};
use fairgrasp_rl::sac::{Sac, SacConfig};
use fairgrasp_rl::td3::{Td3, Td3Config};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;
use tract_onnx::prelude::{
    Framework, InferenceModelExt, IntoRunnable, IntoTValue, Tensor as TractTensor,
};

/// The bound on |ONNX − our inference|.
const TOLERANCE: f32 = 1e-5;
const OBSERVATIONS: usize = 1000;

/// A model of `algo` for `env_id` with random weights large enough that actions leave
/// `[-1, 1]`, and (when `normalize`) statistics far from the identity.
struct Case {
    algo: &'static str,
    env_id: &'static str,
    env: serde_json::Value,
    activation: Activation,
    normalize: bool,
}

fn model(case: &Case, seed: u64) -> (ModelMeta, TensorMap) {
    let env = registry::make(case.env_id, &env_table(&case.env).unwrap()).unwrap();
    let (obs_dim, act_dim) = (env.observation_space().dim(), env.action_space().dim());
    let net_arch = vec![64, 32];
    let (algo, weights) = match case.algo {
        "ppo" => {
            let config = PpoConfig {
                net_arch,
                activation: case.activation,
                ..PpoConfig::default()
            };
            let learner = Ppo::new(config.clone(), obs_dim, act_dim, 1, seed).unwrap();
            (AlgoConfig::Ppo(config), learner.weights().unwrap())
        }
        "td3" => {
            let config = Td3Config {
                net_arch,
                activation: case.activation,
                buffer_size: 100,
                batch_size: 10,
                ..Td3Config::default()
            };
            let learner = Td3::new(config.clone(), obs_dim, act_dim, 1, seed).unwrap();
            (AlgoConfig::Td3(config), learner.weights().unwrap())
        }
        _ => {
            let config = SacConfig {
                net_arch,
                activation: case.activation,
                buffer_size: 100,
                batch_size: 10,
                ..SacConfig::default()
            };
            let learner = Sac::new(config.clone(), obs_dim, act_dim, 1, seed).unwrap();
            (AlgoConfig::Sac(config), learner.weights().unwrap())
        }
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // In name order, so the seed alone fixes every value (a map's order varies by process).
    let mut weights: Vec<(String, Tensor)> = weights.into_iter().collect();
    weights.sort_by(|a, b| a.0.cmp(&b.0));
    let weights = weights
        .into_iter()
        .map(|(name, t)| {
            let dims = t.dims().to_vec();
            // Weights of std √2/√fan_in (the initial scale, which training roughly keeps):
            // pre-activations of a few units, means often beyond ±1.
            let std = match dims.as_slice() {
                [_, fan_in] => (2.0 / *fan_in as f32).sqrt(),
                _ => 0.5,
            };
            let n: usize = dims.iter().product();
            let values: Vec<f32> = (0..n).map(|_| std * standard_normal(&mut rng)).collect();
            (name, Tensor::from_vec(values, dims, &Device::Cpu).unwrap())
        })
        .collect();
    let normalization = case.normalize.then(|| {
        let mean = (0..obs_dim).map(|_| rng.random_range(-2.0..2.0)).collect();
        // Variances over six orders of magnitude, one of them zero (ε alone scales it).
        let mut var: Vec<f64> = (0..obs_dim)
            .map(|_| 10f64.powf(rng.random_range(-4.0..2.0)))
            .collect();
        var[0] = 0.0;
        let mut state = VecNormalizeState::new(obs_dim, VecNormalizeConfig::default()).unwrap();
        state.obs_rms = RunningMeanStd::from_parts(mean, var, 1234.0).unwrap();
        state.to_json()
    });
    let meta = ModelMeta {
        format_version: FORMAT_VERSION,
        algo,
        obs_dim,
        act_dim,
        env_id: case.env_id.into(),
        env: case.env.clone(),
        normalization,
        num_timesteps: 4096,
        train_seed: 1,
        n_envs: 1,
        privileged_dim: 0,
        pixel_actor: None,
    };
    (meta, weights)
}

/// `n` observations for `policy`: drawn around its statistics (normalised values of spread 2,
/// as a trained policy sees), with outliers far beyond the normalisation clip (±1e4: a fifth of
/// the values in one row in ten), and one row in ten all zero.
fn observations(policy: &Policy, n: usize, seed: u64) -> Vec<f32> {
    let obs_dim = policy.obs_dim();
    let (mean, std): (Vec<f64>, Vec<f64>) = match policy.normalization() {
        Some(stats) => (
            stats.obs_rms.mean().to_vec(),
            stats.obs_rms.var().iter().map(|v| v.sqrt()).collect(),
        ),
        None => (vec![0.0; obs_dim], vec![1.0; obs_dim]),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(n * obs_dim);
    for row in 0..n {
        for k in 0..obs_dim {
            let typical = (mean[k] + 2.0 * std[k] * standard_normal(&mut rng) as f64) as f32;
            out.push(match row % 10 {
                0 if policy.normalization().is_some() && rng.random_bool(0.2) => {
                    rng.random_range(-1e4..1e4)
                }
                1 => 0.0,
                _ => typical,
            });
        }
    }
    out
}

/// Runs the ONNX file with tract on `obs` (`n × obs_dim`): (action, env_action).
fn run_onnx(path: &Path, obs: &[f32], obs_dim: usize) -> (Vec<f32>, Vec<f32>) {
    let model = tract_onnx::onnx()
        .model_for_path(path)
        .unwrap()
        .into_optimized()
        .unwrap()
        .into_runnable()
        .unwrap();
    let input = TractTensor::from_shape(&[obs.len() / obs_dim, obs_dim], obs).unwrap();
    let outputs = model.run(vec![input.into_tvalue()].into()).unwrap();
    let values = |i: usize| {
        let view = outputs[i].to_plain_array_view::<f32>().unwrap();
        view.iter().copied().collect::<Vec<f32>>()
    };
    (values(0), values(1))
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// Exports `case` to ONNX and compares tract's outputs with `Policy::act` and with the
/// trainer's clip-and-rescale path, over [`OBSERVATIONS`] observations.
fn check_onnx(case: &Case) {
    let (meta, weights) = model(case, 7);
    let mut policy = Policy::from_parts(meta, &weights).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("policy.onnx");
    export_policy(&policy, Format::Onnx, &path).unwrap();

    let obs_dim = policy.obs_dim();
    let obs = observations(&policy, OBSERVATIONS, 11);
    let (action, env_action) = run_onnx(&path, &obs, obs_dim);

    let table = env_table(policy.env_config()).unwrap();
    let env = RescaleAction::new(registry::make(policy.env_id(), &table).unwrap()).unwrap();
    let (mut want, mut want_env) = (Vec::new(), Vec::new());
    for row in obs.chunks(obs_dim) {
        let mut a = policy.act(row, true).unwrap();
        want.extend_from_slice(&a);
        // What `fairgrasp_rl::train::evaluate` hands the environment.
        env.action_space().clip(&mut a);
        want_env.extend(env.to_inner_action(&a).unwrap());
    }
    let diff = max_abs_diff(&action, &want);
    let env_diff = max_abs_diff(&env_action, &want_env);
    eprintln!(
        "{} {} ({:?}, normalised: {}): max |diff| action {diff:e}, env_action {env_diff:e}",
        case.algo, case.env_id, case.activation, case.normalize
    );
    assert!(diff <= TOLERANCE, "action differs by {diff}");
    assert!(env_diff <= TOLERANCE, "env_action differs by {env_diff}");
    // The check means something: actions leave [-1, 1] (PPO) or come near its ends (SAC), so
    // the clip and both ends of the box are exercised.
    let beyond = want.iter().filter(|a| a.abs() > 0.95).count();
    assert!(beyond > OBSERVATIONS / 20, "only {beyond} large actions");
    // A single observation runs too (the batch size is free).
    let (one, _) = run_onnx(&path, &obs[..obs_dim], obs_dim);
    assert!(max_abs_diff(&one, &want[..policy.act_dim()]) <= TOLERANCE);

    let proto = tract_onnx::onnx().proto_model_for_path(&path).unwrap();
    assert_eq!(proto.producer_name, "fairgrasp");
    let property = |key: &str| {
        proto
            .metadata_props
            .iter()
            .find(|p| p.key == key)
            .map(|p| p.value.clone())
            .unwrap_or_else(|| panic!("no metadata `{key}`"))
    };
    assert_eq!(property("env_id"), case.env_id);
    assert_eq!(property("algo"), case.algo);
    assert_eq!(property("obs_dim"), obs_dim.to_string());
    assert_eq!(property("normalized"), case.normalize.to_string());
    let config: serde_json::Value = serde_json::from_str(&property("env_config")).unwrap();
    assert_eq!(&config, policy.env_config());
    let outputs: Vec<&str> = proto
        .graph
        .as_ref()
        .unwrap()
        .output
        .iter()
        .map(|o| o.name.as_str())
        .collect();
    assert_eq!(outputs, [OUTPUT_ACTION, OUTPUT_ENV_ACTION]);
}

#[test]
fn onnx_ppo_joint_policy_matches_our_inference() {
    let case = Case {
        algo: "ppo",
        env_id: "FaArmGrasp-v0",
        env: serde_json::json!({}),
        activation: Activation::Tanh,
        normalize: true,
    };
    check_onnx(&case);
}

#[test]
fn onnx_sac_cartesian_policy_matches_our_inference() {
    let case = Case {
        algo: "sac",
        env_id: "FaArmGrasp-v0",
        env: serde_json::json!({ "control": { "action_mode": "cartesian" } }),
        activation: Activation::Relu,
        normalize: true,
    };
    check_onnx(&case);
}

#[test]
fn onnx_td3_cartesian_policy_matches_our_inference() {
    let case = Case {
        algo: "td3",
        env_id: "FaArmGrasp-v0",
        env: serde_json::json!({ "control": { "action_mode": "cartesian" } }),
        activation: Activation::Relu,
        normalize: true,
    };
    check_onnx(&case);
}

#[test]
fn onnx_policy_without_normalisation_matches_our_inference() {
    let case = Case {
        algo: "ppo",
        env_id: "Pendulum-v1",
        env: serde_json::json!({}),
        activation: Activation::Relu,
        normalize: false,
    };
    check_onnx(&case);
}

/// A tensor of the exported safetensors file as f64 values, with its shape.
fn read_tensor(file: &safetensors::SafeTensors<'_>, name: &str) -> (Vec<usize>, Vec<f64>) {
    let view = file.tensor(name).unwrap_or_else(|e| panic!("{name}: {e}"));
    let values = match view.dtype() {
        safetensors::Dtype::F32 => view
            .data()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()) as f64)
            .collect(),
        safetensors::Dtype::F64 => view
            .data()
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
            .collect(),
        other => panic!("{name} is {other:?}"),
    };
    (view.shape().to_vec(), values)
}

#[test]
fn safetensors_export_holds_the_whole_deterministic_policy() {
    let case = Case {
        algo: "sac",
        env_id: "Pendulum-v1",
        env: serde_json::json!({}),
        activation: Activation::Tanh,
        normalize: true,
    };
    let (meta, weights) = model(&case, 3);
    let dir = tempfile::tempdir().unwrap();
    let model_dir = dir.path().join("model");
    save_model(&model_dir, &weights, &meta).unwrap();
    let written = export(&model_dir, Format::Safetensors, None).unwrap();
    assert_eq!(written, model_dir.join("policy.safetensors"));
    let bytes = std::fs::read(&written).unwrap();
    let file = safetensors::SafeTensors::deserialize(&bytes).unwrap();

    let mut names = file.names();
    names.sort();
    let want = [
        "env_action.high",
        "env_action.low",
        "obs_norm.mean",
        "obs_norm.var",
        "policy.l0.bias",
        "policy.l0.weight",
        "policy.l1.bias",
        "policy.l1.weight",
        "policy.l2.bias",
        "policy.l2.weight",
    ];
    assert_eq!(names, want);
    let (obs_dim, act_dim) = (meta.obs_dim, meta.act_dim);
    // Weights as saved; of SAC's last layer, the mean rows only.
    let saved = |name: &str| -> Vec<f64> {
        let t = weights[name]
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        t.into_iter().map(f64::from).collect()
    };
    assert_eq!(
        read_tensor(&file, "policy.l0.weight"),
        (vec![64, obs_dim], saved("actor.l0.weight"))
    );
    assert_eq!(
        read_tensor(&file, "policy.l1.bias"),
        (vec![32], saved("actor.l1.bias"))
    );
    let (shape, last) = read_tensor(&file, "policy.l2.weight");
    assert_eq!(shape, [act_dim, 32]);
    assert_eq!(last, saved("actor.l2.weight")[..act_dim * 32]);
    let stats = VecNormalizeState::from_json(meta.normalization.as_ref().unwrap()).unwrap();
    assert_eq!(read_tensor(&file, "obs_norm.var").1, stats.obs_rms.var());
    assert_eq!(
        read_tensor(&file, "env_action.high"),
        (vec![act_dim], vec![2.0])
    );

    let (_, header) = safetensors::SafeTensors::read_metadata(&bytes).unwrap();
    let info = header.metadata().as_ref().unwrap();
    for (key, value) in [
        ("format", "fairgrasp.policy"),
        ("env_id", "Pendulum-v1"),
        ("algo", "sac"),
        ("obs_dim", "3"),
        ("act_dim", "1"),
        ("layers", "policy.l0,policy.l1,policy.l2"),
        ("activation", "tanh"),
        ("head", "tanh"),
        ("normalized", "true"),
        ("obs_norm_clip", "10"),
    ] {
        assert_eq!(info.get(key).map(String::as_str), Some(value), "{key}");
    }

    // The file alone gives the policy's actions, by the formula its documentation states.
    let eps: f64 = info["obs_norm_epsilon"].parse().unwrap();
    let clip: f64 = info["obs_norm_clip"].parse().unwrap();
    let (mean, var) = (
        read_tensor(&file, "obs_norm.mean").1,
        read_tensor(&file, "obs_norm.var").1,
    );
    let layers: Vec<(Vec<usize>, Vec<f64>, Vec<f64>)> = info["layers"]
        .split(',')
        .map(|l| {
            let (shape, w) = read_tensor(&file, &format!("{l}.weight"));
            (shape, w, read_tensor(&file, &format!("{l}.bias")).1)
        })
        .collect();
    let mut policy = Policy::load(&model_dir).unwrap();
    let obs = observations(&policy, 200, 5);
    for row in obs.chunks(obs_dim) {
        let mut x: Vec<f64> = row
            .iter()
            .zip(mean.iter().zip(&var))
            .map(|(&o, (m, v))| ((o as f64 - m) / (v + eps).sqrt()).clamp(-clip, clip))
            .collect();
        for (i, (shape, w, b)) in layers.iter().enumerate() {
            x = (0..shape[0])
                .map(|r| {
                    b[r] + (0..shape[1])
                        .map(|c| w[r * shape[1] + c] * x[c])
                        .sum::<f64>()
                })
                .collect();
            if i + 1 < layers.len() {
                x.iter_mut().for_each(|v| *v = v.tanh());
            }
        }
        let action: Vec<f32> = x.iter().map(|v| v.tanh() as f32).collect();
        let want = policy.act(row, true).unwrap();
        assert!(
            max_abs_diff(&action, &want) <= TOLERANCE,
            "{action:?} vs {want:?}"
        );
    }
}

#[test]
fn the_default_onnx_path_is_in_the_model_directory_and_bad_models_are_named() {
    let case = Case {
        algo: "ppo",
        env_id: "Pendulum-v1",
        env: serde_json::json!({}),
        activation: Activation::Tanh,
        normalize: false,
    };
    let (meta, weights) = model(&case, 1);
    let dir = tempfile::tempdir().unwrap();
    let model_dir = dir.path().join("run").join("best");
    save_model(&model_dir, &weights, &meta).unwrap();
    // A run directory stands for its best model.
    let written = export(&dir.path().join("run"), Format::Onnx, None).unwrap();
    assert_eq!(written, model_dir.join("policy.onnx"));
    let custom = dir.path().join("out").join("pendulum.onnx");
    assert_eq!(
        export(&model_dir, Format::Onnx, Some(&custom)).unwrap(),
        custom
    );
    assert_eq!(
        std::fs::read(&custom).unwrap(),
        std::fs::read(&written).unwrap()
    );

    let missing = dir.path().join("no-such-model");
    let err = export(&missing, Format::Onnx, None)
        .unwrap_err()
        .to_string();
    assert!(err.contains(&missing.display().to_string()), "{err}");
    // A model whose weights do not fit its description names the directory and the tensor.
    let broken = dir.path().join("broken");
    let mut wrong = weights.clone();
    wrong.remove("pi.l1.bias");
    save_model(&broken, &wrong, &meta).unwrap();
    let err = export(&broken, Format::Safetensors, None)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(&broken.display().to_string()) && err.contains("pi.l1.bias"),
        "{err}"
    );
    assert!(!broken.join("policy.safetensors").exists());
    // A model of an environment the registry refuses names the problem.
    let mut odd = meta.clone();
    odd.env = serde_json::json!({ "gravity": 3 });
    let odd_dir = dir.path().join("odd");
    save_model(&odd_dir, &weights, &odd).unwrap();
    let err = export(&odd_dir, Format::Onnx, None)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("Pendulum-v1") && err.contains("gravity"),
        "{err}"
    );

    let err = "pytorch".parse::<Format>().unwrap_err().to_string();
    assert!(
        err.contains("pytorch") && err.contains("onnx or safetensors"),
        "{err}"
    );
}

/// A camera policy's ONNX graph takes the state and one `u8` input per camera (the keys of the
/// environment's `Dict` observation) and gives the actions of `Policy::act_with_images`.
#[test]
fn onnx_camera_policy_on_state_and_images_matches_our_inference() {
    use fairgrasp_deploy::export::onnx::STATE_INPUT;
    use fairgrasp_rl::model::PixelActorMeta;
    use fairgrasp_rl::policies::pixel_actor::{PixelActor, PixelActorConfig};

    let env_config = serde_json::json!({
        "camera": { "mode": "rgbd+state", "width": 32, "height": 32, "wrist": { "enabled": true } }
    });
    let table = env_table(&env_config).unwrap();
    let mut env = RescaleAction::new(registry::make("FaArmGrasp-v0", &table).unwrap()).unwrap();
    let space = env.image_space().unwrap().clone();
    assert!(space.views.len() >= 2, "{}", space.describe());
    let (state_dim, act_dim) = (env.observation_space().dim(), env.action_space().dim());
    let actor_config = PixelActorConfig {
        features: 16,
        net_arch: vec![32],
        ..PixelActorConfig::default()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut actor = PixelActor::new(&actor_config, &space, state_dim, act_dim, &mut rng).unwrap();
    // Observations of real episodes under random actions.
    let (mut states, mut images) = (Vec::new(), Vec::new());
    let (mut obs, _) = env.reset(Some(1)).unwrap();
    for _ in 0..40 {
        states.extend_from_slice(&obs);
        images.extend_from_slice(env.image().unwrap());
        let action: Vec<f32> = (0..act_dim).map(|_| rng.random_range(-1.0..1.0)).collect();
        let step = env.step(&action).unwrap();
        obs = if step.terminated || step.truncated {
            env.reset(None).unwrap().0
        } else {
            step.obs
        };
    }
    let n = states.len() / state_dim;
    actor.fit_state_scale(&states, 1e-3);
    // Output weights 300 times the initial scale, so that actions leave [-1, 1].
    let mut weights = actor.weights();
    let last = format!("head.{}.weight", actor_config.net_arch.len());
    weights.insert(last.clone(), (weights[&last].clone() * 300.0).unwrap());
    let meta = ModelMeta {
        format_version: FORMAT_VERSION,
        algo: AlgoConfig::default(),
        obs_dim: state_dim,
        act_dim,
        env_id: "FaArmGrasp-v0".into(),
        env: env_config,
        normalization: None,
        num_timesteps: 0,
        train_seed: 0,
        n_envs: 1,
        privileged_dim: 0,
        pixel_actor: Some(PixelActorMeta {
            actor: actor_config,
            images: space.clone(),
        }),
    };
    let mut policy = Policy::from_parts(meta, &weights).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("policy.onnx");
    export_policy(&policy, Format::Onnx, &path).unwrap();

    let model = tract_onnx::onnx()
        .model_for_path(&path)
        .unwrap()
        .into_optimized()
        .unwrap()
        .into_runnable()
        .unwrap();
    let proto = tract_onnx::onnx().proto_model_for_path(&path).unwrap();
    let inputs: Vec<String> = (proto.graph.as_ref().unwrap().input.iter())
        .map(|i| i.name.clone())
        .collect();
    let mut names = vec![STATE_INPUT.to_string()];
    names.extend(space.views.iter().map(|v| v.name.clone()));
    assert_eq!(inputs, names);
    let run = |rows: usize| {
        let mut feed = vec![
            TractTensor::from_shape(&[rows, state_dim], &states[..rows * state_dim])
                .unwrap()
                .into_tvalue(),
        ];
        for (v, view) in space.views.iter().enumerate() {
            let range = space.range(v);
            let bytes: Vec<u8> = (images.chunks_exact(space.len()).take(rows))
                .flat_map(|obs| obs[range.clone()].iter().copied())
                .collect();
            let shape = [
                rows,
                view.height as usize,
                view.width as usize,
                view.channels as usize,
            ];
            feed.push(
                TractTensor::from_shape(&shape, &bytes)
                    .unwrap()
                    .into_tvalue(),
            );
        }
        let outputs = model.run(feed.into()).unwrap();
        let values = |i: usize| {
            let view = outputs[i].to_plain_array_view::<f32>().unwrap();
            view.iter().copied().collect::<Vec<f32>>()
        };
        (values(0), values(1))
    };
    let (action, env_action) = run(n);
    let (mut want, mut want_env) = (Vec::new(), Vec::new());
    for (state, image) in states.chunks(state_dim).zip(images.chunks(space.len())) {
        let mut a = policy.act_with_images(state, Some(image), true).unwrap();
        want.extend_from_slice(&a);
        env.action_space().clip(&mut a);
        want_env.extend(env.to_inner_action(&a).unwrap());
    }
    let diff = max_abs_diff(&action, &want);
    let env_diff = max_abs_diff(&env_action, &want_env);
    eprintln!(
        "camera policy ({}): max |diff| action {diff:e}, env_action {env_diff:e}",
        space.describe()
    );
    // The convolutions sum in another order than our kernels: not bit for bit.
    assert!(diff <= 1e-4, "action differs by {diff}");
    assert!(env_diff <= 1e-4, "env_action differs by {env_diff}");
    let beyond = want.iter().filter(|a| a.abs() > 1.0).count();
    assert!(
        beyond > want.len() / 20,
        "only {beyond} actions beyond [-1, 1]"
    );
    let (one, _) = run(1);
    assert!(max_abs_diff(&one, &want[..act_dim]) <= 1e-4);

    // Its safetensors export is refused with the reason.
    let err = export_policy(
        &policy,
        Format::Safetensors,
        &dir.path().join("p.safetensors"),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.contains("ONNX only"), "{err}");
}
