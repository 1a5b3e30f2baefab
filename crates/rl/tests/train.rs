//! A short training run writes what SB3 users expect, readable by an event-file reader; runs
//! resume from checkpoints; saved models load back or fail with a clear error.

use fairgrasp_rl::Algo;
use fairgrasp_rl::Policy;
use fairgrasp_rl::logger::read_scalars;
use fairgrasp_rl::model::load_tensors;
use fairgrasp_rl::train::{
    Callback, CallbackContext, StopReason, TrainConfig, checkpoints, resume, train, train_with,
};
use std::ops::ControlFlow;
use std::path::Path;

/// A tiny PPO run: 2 envs × 128 steps per iteration, 4 minibatches × 2 epochs per update.
fn tiny_config(total: u64) -> TrainConfig {
    tiny_config_with(total, &[]).unwrap()
}

/// [`tiny_config`] with more `key=value` overrides.
fn tiny_config_with(total: u64, overrides: &[&str]) -> fairgrasp_rl::error::Result<TrainConfig> {
    let overrides: Vec<String> = ["env.reward.kind=staged"]
        .iter()
        .chain(overrides)
        .map(|o| o.to_string())
        .collect();
    TrainConfig::from_toml_str(
        &format!(
            "total_timesteps = {total}\nn_envs = 2\nthreads = 1\ncheckpoint_freq = 512\n\
             [eval]\nfreq = 512\nepisodes = 1\n\
             [ppo]\nn_steps = 128\nbatch_size = 64\nn_epochs = 2\n\
             [env.task]\nmax_episode_steps = 20\n"
        ),
        &overrides,
    )
}

/// The optimiser's step counter stored in a checkpoint.
fn adam_steps(checkpoint: &Path) -> f64 {
    let state = load_tensors(&checkpoint.join("training_state.safetensors")).unwrap();
    state["adam.step"].to_vec1::<f64>().unwrap()[0]
}

/// Every scalar of a run's TensorBoard event file.
fn run_scalars(run: &Path) -> Vec<fairgrasp_rl::logger::ScalarEvent> {
    let tb = std::fs::read_dir(run.join("tb"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    read_scalars(&tb).unwrap()
}

/// The `time/total_timesteps` column of progress.csv.
fn logged_steps(run: &Path) -> Vec<f64> {
    let text = std::fs::read_to_string(run.join("progress.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = header
        .iter()
        .position(|c| *c == "time/total_timesteps")
        .unwrap();
    lines
        .map(|l| l.split(',').nth(col).unwrap().parse().unwrap())
        .collect()
}

#[test]
fn a_short_run_writes_config_logs_best_model_and_checkpoints() {
    let dir = tempfile::tempdir().unwrap();
    let config = tiny_config(1024);
    let summary = train(&config, dir.path(), |_| {}).unwrap();
    assert!(summary.num_timesteps >= 1024);
    for file in [
        "config.toml",
        "progress.csv",
        "best/model.safetensors",
        "best/model.json",
        "final/model.json",
    ] {
        assert!(dir.path().join(file).is_file(), "{file} missing");
    }
    let checkpoint = dir.path().join("checkpoints/step_512");
    for file in [
        "model.safetensors",
        "model.json",
        "training_state.safetensors",
        "trainer_state.json",
    ] {
        assert!(checkpoint.join(file).is_file(), "checkpoint lacks {file}");
    }
    // The effective configuration is saved and loads back equal.
    let saved = std::fs::read_to_string(dir.path().join("config.toml")).unwrap();
    assert_eq!(TrainConfig::from_toml_str(&saved, &[]).unwrap(), config);

    let scalars = run_scalars(dir.path());
    for tag in [
        "rollout/ep_rew_mean",
        "rollout/success_rate",
        "train/policy_gradient_loss",
        "train/value_loss",
        "train/entropy_loss",
        "train/approx_kl",
        "train/clip_fraction",
        "train/explained_variance",
        "train/learning_rate",
        "train/std",
        "time/fps",
        "time/time_elapsed",
        "eval/success_rate",
        "eval/mean_reward",
        "eval/mean_ep_length",
        // The task's own values, by name, without the driver knowing them.
        "rollout/max_grasped",
        "rollout/max_lift",
        "eval/lift",
        "eval/ee_object_distance",
    ] {
        assert!(
            scalars.iter().any(|s| s.tag == tag),
            "no {tag} in the event file"
        );
    }
    assert!(
        scalars
            .iter()
            .all(|s| s.value.is_finite() || s.tag == "train/explained_variance")
    );
}

/// A caller's callback: counts the vector steps and iterations it saw, and stops the run once
/// `stop_at` environment steps are done.
struct StopAt {
    stop_at: u64,
    vector_steps: u64,
    iterations: Vec<u64>,
}

impl Callback for StopAt {
    fn on_step(&mut self, _step: &fairgrasp_env::VecStep<'_>) {
        self.vector_steps += 1;
    }

    fn on_iteration(
        &mut self,
        ctx: &mut CallbackContext<'_>,
    ) -> fairgrasp_rl::error::Result<ControlFlow<StopReason>> {
        self.iterations.push(ctx.num_timesteps);
        // What a callback can read: the run's settings and the model as it is now.
        assert_eq!(ctx.config.n_envs, 2);
        assert_eq!(ctx.model()?.0.num_timesteps, ctx.num_timesteps);
        Ok(match ctx.num_timesteps >= self.stop_at {
            true => ControlFlow::Break(StopReason::Requested),
            false => ControlFlow::Continue(()),
        })
    }
}

#[test]
fn a_callback_passed_to_the_library_sees_every_step_and_stops_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    let mut callback = StopAt {
        stop_at: 512,
        vector_steps: 0,
        iterations: Vec::new(),
    };
    let summary = train_with(&tiny_config(100_000), &run, vec![Box::new(&mut callback)]).unwrap();
    // 2 envs × 128 steps per iteration: the second iteration reaches 512 and stops the run.
    assert_eq!(callback.iterations, [256, 512]);
    assert!(summary.stopped && !summary.reached_threshold);
    assert_eq!(summary.num_timesteps, 512);
    assert_eq!(callback.vector_steps, 256);
    // Stopped runs end as finished ones do: the final model and the summary are written.
    assert_eq!(
        Policy::load(&run.join("final"))
            .unwrap()
            .meta()
            .num_timesteps,
        512
    );
    assert!(run.join("summary.json").is_file());
}

#[test]
fn evaluations_and_confirmations_play_the_eval_env_laid_over_the_training_env() {
    // Training episodes last 20 steps; `eval.env` cuts the evaluated ones to 7. An untrained
    // policy never succeeds, so every evaluated episode runs to its limit.
    let dir = tempfile::tempdir().unwrap();
    let mut config = tiny_config_with(1024, &["eval.env.task.max_episode_steps=7"]).unwrap();
    config.checkpoint_freq = 0;
    config.eval.success_threshold = Some(0.0);
    config.eval.confirm_episodes = 3;
    config.eval.confirm_lower_bound = 1.0;
    assert_eq!(
        config.eval_env()["task"]["max_episode_steps"].as_integer(),
        Some(7)
    );
    assert_eq!(
        config.env["task"]["max_episode_steps"].as_integer(),
        Some(20)
    );
    assert_eq!(config.eval_env()["reward"]["kind"].as_str(), Some("staged"));
    let summary = train(&config, dir.path(), |_| {}).unwrap();
    let best = summary.best.unwrap();
    assert!(best.confirmed && best.episodes == 3, "{best:?}");
    assert_eq!(best.mean_length, 7.0);
    let lengths: Vec<f32> = (run_scalars(dir.path()).iter())
        .filter(|s| s.tag == "eval/mean_ep_length")
        .map(|s| s.value)
        .collect();
    assert_eq!(lengths, [7.0, 7.0]);
    // The model keeps the training env: its own evaluations play 20-step episodes.
    let policy = Policy::load(&dir.path().join("final")).unwrap();
    let saved = fairgrasp_rl::model::env_table(policy.env_config()).unwrap();
    assert_eq!(saved["task"]["max_episode_steps"].as_integer(), Some(20));
}

#[test]
fn training_config_errors_name_the_key() {
    for (text, key) in [
        ("n_envs = 0\n", "n_envs"),
        ("[ppo]\nbatch_size = 0\n", "ppo.batch_size"),
        ("[ppo]\nlearning_rat = 0.1\n", "learning_rat"),
        (
            "[env.control]\nmax_joint_delta = 9.0\n",
            "env.control.max_joint_delta",
        ),
        ("[env.task]\nmax_joint_delta = 9.0\n", "max_joint_delta"),
        ("env_id = \"FaArmJuggle-v9\"\n", "FaArmJuggle-v9"),
        ("[eval]\nrecord_size = [8, 8]\n", "eval.record_size"),
        (
            "[eval.env.control]\nmax_joint_delta = 9.0\n",
            "eval.env.control.max_joint_delta",
        ),
        (
            "[eval.env.task]\nobservation = \"seed23\"\n",
            "`eval.env`: changes the (observation, action) sizes from (40, 7) to (23, 7)",
        ),
    ] {
        let err = TrainConfig::from_toml_str(text, &[])
            .err()
            .unwrap_or_else(|| panic!("{text} accepted"))
            .to_string();
        assert!(err.contains(key), "{text}: {err}");
    }
}

#[test]
fn every_shipped_training_config_is_accepted() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs");
    let mut checked = Vec::new();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap();
        // The scene and env files are other kinds of configuration.
        if !text.contains("total_timesteps") {
            continue;
        }
        TrainConfig::from_toml_str(&text, &[])
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        checked.push(path.file_name().unwrap().to_string_lossy().into_owned());
    }
    assert!(
        checked.iter().any(|n| n == "ppo_deploy_kinematic.toml"),
        "{checked:?}"
    );
}

#[test]
fn a_resumed_run_continues_counters_optimizer_and_logs_from_the_last_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path();
    // Without a checkpoint there is nothing to resume.
    std::fs::create_dir_all(run).unwrap();
    std::fs::write(run.join("config.toml"), "").unwrap();
    let err = resume(run, &[], |_| {}).err().unwrap().to_string();
    assert!(err.contains("no complete checkpoint"), "{err}");

    // "Interrupted" after 1024 steps: checkpoints at 512 and 1024, plus an unfinished one.
    train(&tiny_config(1024), run, |_| {}).unwrap();
    std::fs::create_dir_all(run.join("checkpoints/.step_1280.partial")).unwrap();
    std::fs::create_dir_all(run.join("checkpoints/step_1536")).unwrap(); // no trainer state
    let steps: Vec<u64> = checkpoints(run).iter().map(|c| c.0).collect();
    assert_eq!(steps, [512, 1024]);
    // 1024 steps = 4 iterations of 256, each 2 epochs × 4 minibatches.
    assert_eq!(adam_steps(&run.join("checkpoints/step_1024")), 32.0);

    let summary = resume(run, &["total_timesteps=2048".into()], |_| {}).unwrap();
    assert_eq!(summary.resumed_from, Some(1024));
    assert_eq!(summary.num_timesteps, 2048);
    // The optimiser went on counting from the checkpoint (a fresh one would stand at 32).
    assert_eq!(adam_steps(&run.join("checkpoints/step_2048")), 64.0);
    let saved = std::fs::read_to_string(run.join("config.toml")).unwrap();
    assert_eq!(
        TrainConfig::from_toml_str(&saved, &[])
            .unwrap()
            .total_timesteps,
        2048
    );
    // Training rows are logged once per step count, in order, across the resume.
    let logged = logged_steps(run);
    let train_rows: Vec<f64> = logged
        .iter()
        .copied()
        .filter(|s| s % 256.0 == 0.0)
        .collect();
    assert!(train_rows.contains(&1280.0) && train_rows.contains(&2048.0));
    let mut sorted = logged.clone();
    sorted.sort_by(f64::total_cmp);
    assert_eq!(logged, sorted, "progress.csv out of order: {logged:?}");
    // Two event files: the first attempt's and the resumed one's.
    assert_eq!(std::fs::read_dir(run.join("tb")).unwrap().count(), 2);
}

#[test]
fn saved_models_load_and_corrupt_or_mismatched_ones_fail_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path();
    train(&tiny_config(512), run, |_| {}).unwrap();
    // A run directory means its best model; it acts on raw observations.
    let mut model = Policy::load(run).unwrap();
    assert_eq!(model.meta().algo.algo(), Algo::Ppo);
    assert_eq!(model.env_id(), fairgrasp_rl::env::ENV_ID);
    assert_eq!(model.dir(), Some(run.join("best").as_path()));
    let action = model.act(&vec![0.0; model.obs_dim()], true).unwrap();
    assert_eq!(action.len(), model.act_dim());
    let err = model.act(&[0.0; 3], true).err().unwrap().to_string();
    assert!(err.contains("3 values") && err.contains("best"), "{err}");
    let mut nan = vec![0.0; model.obs_dim()];
    nan[2] = f32::NAN;
    let err = model.act(&nan, true).err().unwrap().to_string();
    assert!(err.contains("value 2 is NaN"), "{err}");

    let copy = |name: &str| {
        let target = run.join(name);
        std::fs::create_dir_all(&target).unwrap();
        for f in ["model.json", "model.safetensors"] {
            std::fs::copy(run.join("best").join(f), target.join(f)).unwrap();
        }
        target
    };
    let corrupt = copy("corrupt");
    std::fs::write(corrupt.join("model.safetensors"), b"not a tensor file").unwrap();
    let err = Policy::load(&corrupt).err().unwrap().to_string();
    assert!(err.contains("model.safetensors"), "{err}");

    let truncated = copy("truncated");
    std::fs::write(truncated.join("model.json"), b"{\"format_version\": 1").unwrap();
    let err = Policy::load(&truncated).err().unwrap().to_string();
    assert!(err.contains("not a fairgrasp model"), "{err}");

    let mismatched = copy("mismatched");
    let json = std::fs::read_to_string(mismatched.join("model.json")).unwrap();
    let original = format!("\"obs_dim\": {}", model.obs_dim());
    assert!(json.contains(&original));
    let json = json.replacen(&original, "\"obs_dim\": 23", 1);
    std::fs::write(mismatched.join("model.json"), json).unwrap();
    let err = Policy::load(&mismatched).err().unwrap().to_string();
    assert!(err.contains("shape"), "{err}");

    let err = Policy::load(&run.join("nowhere"))
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("no model here"), "{err}");
}

#[test]
fn the_same_seed_trains_the_same_weights() {
    let weights = |seed: u64| {
        let dir = tempfile::tempdir().unwrap();
        let mut config = tiny_config(512);
        config.seed = seed;
        train(&config, dir.path(), |_| {}).unwrap();
        let tensors = load_tensors(&dir.path().join("final/model.safetensors")).unwrap();
        let mut names: Vec<&String> = tensors.keys().collect();
        names.sort();
        names
            .into_iter()
            .flat_map(|n| tensors[n].flatten_all().unwrap().to_vec1::<f32>().unwrap())
            .collect::<Vec<f32>>()
    };
    let (a, b) = (weights(7), weights(7));
    assert_eq!(a, b, "two runs with seed 7 differ");
    assert_ne!(a, weights(8), "seeds 7 and 8 trained the same weights");
}

/// The driver learns a classic task named by id, and its saved model records that id: the
/// same code path as the grasp runs above, through the registry.
#[test]
fn the_driver_learns_a_classic_task_named_by_id() {
    let dir = tempfile::tempdir().unwrap();
    let config = TrainConfig::from_toml_str(
        "env_id = \"PointReach-v0\"\ntotal_timesteps = 61440\nn_envs = 8\nthreads = 1\n\
         checkpoint_freq = 0\nseed = 7\n\
         [normalize]\nnorm_obs = false\nnorm_reward = false\n\
         [eval]\nfreq = 20480\nepisodes = 20\n\
         [ppo]\nn_steps = 128\nbatch_size = 256\nn_epochs = 10\nlearning_rate = 0.001\n",
        &[],
    )
    .unwrap();
    let summary = train(&config, dir.path(), |_| {}).unwrap();
    let best = summary.best.unwrap();
    // A random policy scores about −50; the learnt one comes close to the goal and stays.
    assert!(best.mean_return > -15.0, "{best:?}");
    assert!(best.final_extras.get("distance").unwrap() < 0.3, "{best:?}");
    let policy = Policy::load(dir.path()).unwrap();
    assert_eq!(policy.env_id(), "PointReach-v0");
    assert_eq!((policy.obs_dim(), policy.act_dim()), (6, 2));
}

/// A short run on each new arm task: built from its id, trained, saved with its id and
/// settings, and evaluated again through the registry from the saved model alone.
#[test]
fn the_driver_runs_the_pick_and_place_and_sorting_tasks() {
    for id in ["FaArmPickPlace-v0", "FaArmSort-v0"] {
        let dir = tempfile::tempdir().unwrap();
        let config = TrainConfig::from_toml_str(
            &format!(
                "env_id = \"{id}\"\ntotal_timesteps = 256\nn_envs = 2\nthreads = 1\n\
                 checkpoint_freq = 0\n[eval]\nfreq = 256\nepisodes = 1\n\
                 [ppo]\nn_steps = 64\nbatch_size = 64\nn_epochs = 1\n\
                 [env.control]\naction_mode = \"cartesian\"\n\
                 [env.task]\nmax_episode_steps = 10\n"
            ),
            &[],
        )
        .unwrap();
        let summary = train(&config, dir.path(), |_| {}).unwrap();
        assert_eq!(summary.num_timesteps, 256, "{id}");
        let mut policy = Policy::load(dir.path()).unwrap();
        assert_eq!(policy.env_id(), id);
        let table = fairgrasp_rl::model::env_table(policy.env_config()).unwrap();
        let again = fairgrasp_rl::train::evaluate(
            &mut |obs, _| policy.act(obs, true),
            id,
            &table,
            1,
            fairgrasp_rl::train::EVAL_SEED_BASE,
        )
        .unwrap();
        // The saved model in the env rebuilt from its own record plays the evaluation that
        // chose it, step for step.
        assert_eq!(Some(again), summary.best, "{id}");
    }
}

#[test]
fn eval_record_writes_a_gif_of_an_evaluation_episode_per_evaluation() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = tiny_config(1024);
    config.eval.record = true;
    config.eval.record_size = [48, 32];
    train(&config, dir.path(), |_| {}).unwrap();
    for steps in [512, 1024] {
        let path = dir.path().join(format!("videos/eval_{steps}.gif"));
        let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut options = gif::DecodeOptions::new();
        options.set_color_output(gif::ColorOutput::RGBA);
        let mut decoder = options.read_info(bytes.as_slice()).unwrap();
        assert_eq!((decoder.width(), decoder.height()), (48, 32));
        let mut frames = 0;
        while decoder.read_next_frame().unwrap().is_some() {
            frames += 1;
        }
        // A frame per state of the 20-step episode (fewer if it ended early), the last one
        // included.
        assert!((2..=21).contains(&frames), "{frames} frames");
    }
    // Recording renders a separate replay: the evaluation's figures match a run without it.
    let plain = tempfile::tempdir().unwrap();
    train(&tiny_config(1024), plain.path(), |_| {}).unwrap();
    let eval_rows = |run: &Path| {
        std::fs::read_to_string(run.join("progress.csv"))
            .unwrap()
            .lines()
            .filter(|l| !l.contains(",,"))
            .count()
    };
    assert_eq!(eval_rows(dir.path()), eval_rows(plain.path()));
    assert_eq!(
        std::fs::read(dir.path().join("best/model.safetensors")).unwrap(),
        std::fs::read(plain.path().join("best/model.safetensors")).unwrap()
    );
}

#[test]
fn the_wilson_lower_bound_matches_its_formula() {
    use fairgrasp_rl::train::wilson_lower_bound;
    // Reference values from the closed form (z = 1.96).
    for (s, n, want) in [
        (200, 200, 0.98115),
        (197, 200, 0.95683),
        (196, 200, 0.94971),
        (49, 50, 0.89505),
    ] {
        let got = wilson_lower_bound(s, n);
        assert!((got - want).abs() < 1e-4, "{s}/{n}: {got}");
    }
    assert_eq!(wilson_lower_bound(0, 10), 0.0);
    assert_eq!(wilson_lower_bound(0, 0), 0.0);
}

#[test]
fn a_threshold_stop_waits_for_its_confirmation_on_validation_seeds() {
    // The threshold (0) is reached at every evaluation; the confirmation's bound decides.
    let run = |bound: f32| {
        let dir = tempfile::tempdir().unwrap();
        let mut config = tiny_config(2048);
        config.checkpoint_freq = 0;
        config.eval.success_threshold = Some(0.0);
        config.eval.confirm_episodes = 3;
        config.eval.confirm_lower_bound = bound;
        let summary = train(&config, dir.path(), |_| {}).unwrap();
        let scalars = run_scalars(dir.path());
        let confirmations = scalars
            .iter()
            .filter(|s| s.tag == "eval/confirmed_lower_bound")
            .count();
        (summary, confirmations)
    };
    // A bound of 0 holds at the first evaluation: the run stops there, its best confirmed.
    let (stopped, confirmations) = run(0.0);
    assert!(stopped.reached_threshold);
    assert_eq!(stopped.num_timesteps, 512);
    assert_eq!(confirmations, 1);
    let best = stopped.best.unwrap();
    assert!(best.confirmed && best.episodes == 3, "{best:?}");
    // No 3 episodes give a lower bound of 1: every evaluation is confirmed, none stops it.
    let (ran_on, confirmations) = run(1.0);
    assert!(!ran_on.reached_threshold);
    assert_eq!(ran_on.num_timesteps, 2048);
    assert_eq!(confirmations, 4);
}

#[test]
fn a_privileged_critic_trains_saves_and_resumes_and_the_policy_reads_the_observation_alone() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path();
    let privileged = [
        "env.readings.enabled=true",
        "env.readings.privileged=true",
        "ppo.privileged_critic=true",
    ];
    train(&tiny_config_with(1024, &privileged).unwrap(), run, |_| {}).unwrap();
    let mut model = Policy::load(run).unwrap();
    let (obs_dim, privileged_dim) = (model.obs_dim(), model.meta().privileged_dim);
    assert_eq!(privileged_dim, obs_dim + 1);
    let weights = load_tensors(&run.join("best/model.safetensors")).unwrap();
    assert_eq!(weights["pi.l0.weight"].dims()[1], obs_dim);
    assert_eq!(weights["vf.l0.weight"].dims()[1], obs_dim + privileged_dim);
    let action = model.act(&vec![0.0; obs_dim], true).unwrap();
    assert_eq!(action.len(), model.act_dim());

    // The critic's running statistics are part of the training state, and a resume goes on.
    let state =
        load_tensors(&run.join("checkpoints/step_1024/training_state.safetensors")).unwrap();
    let count = state["ppo.privileged.count"].to_vec1::<f64>().unwrap()[0];
    assert!(count > 1024.0, "{count}");
    assert_eq!(state["ppo.privileged.mean"].dims(), [privileged_dim]);
    let summary = resume(run, &["total_timesteps=1536".into()], |_| {}).unwrap();
    assert_eq!(summary.num_timesteps, 1536);

    // A privileged critic on an environment that reports no privileged state is refused.
    let other = dir.path().join("refused");
    let config = tiny_config_with(512, &["ppo.privileged_critic=true"]).unwrap();
    let err = train(&config, &other, |_| {}).err().unwrap().to_string();
    assert!(
        err.contains("ppo.privileged_critic") && err.contains("privileged = true"),
        "{err}"
    );
}

/// SHA-256 of a run's final weights: every tensor by name, its shape and its `f32` values.
fn weights_sha256(run: &Path) -> String {
    use sha2::{Digest, Sha256};
    let tensors = load_tensors(&run.join("final/model.safetensors")).unwrap();
    let mut names: Vec<&String> = tensors.keys().collect();
    names.sort();
    let mut hash = Sha256::new();
    for name in names {
        let t = &tensors[name];
        hash.update(name.as_bytes());
        for d in t.dims() {
            hash.update((*d as u64).to_le_bytes());
        }
        for v in t.flatten_all().unwrap().to_vec1::<f32>().unwrap() {
            hash.update(v.to_le_bytes());
        }
    }
    format!("{:x}", hash.finalize())
}

/// Which of gemm's matrix-product kernels this host runs (gemm picks at run time): the same
/// seed trains other SAC and TD3 weights on each (candle's products sum in each kernel's order;
/// PPO's MLPs run one kernel of ours on every host with AVX2 and FMA).
fn gemm_kernel() -> Option<&'static str> {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx512f") {
            return Some("avx512f");
        }
        if std::is_x86_feature_detected!("fma") {
            return Some("fma");
        }
    }
    None
}

/// Short runs of the shipped configs train the weights pinned here, so that a change meant to
/// leave behaviour alone (a refactor, a faster kernel) shows when it does not: the same seed
/// must keep training the same policy for every user. A change that means to move them updates
/// the hashes and says why in its commit. PPO's are one hash on every host with AVX2 and FMA
/// (an AVX-512 build and one with gemm's `x86-v4` feature off trained the same bytes); SAC's
/// and TD3's are pinned per gemm kernel, an AVX-512 host and an AVX2-only one training
/// different weights from the same seed (the `fma` hashes were taken on an AVX-512 host with
/// that feature off, which runs the AVX2 host's kernel). Where neither kernel runs, two runs
/// of the first config must agree.
#[test]
fn short_runs_of_the_shipped_configs_train_pinned_weights() {
    let short = ["threads=1", "checkpoint_freq=1000000", "eval.freq=1000000"];
    let builtin = |algo: &str| {
        fairgrasp_rl::configs::builtin_table(fairgrasp_env::ENV_ID, algo.parse().unwrap())
            .unwrap()
            .to_string()
    };
    // (name, config, overrides, SHA-256: one for every host, or on avx512f and on fma)
    let cases: [(&str, String, &[&str], &[&str]); 4] = [
        (
            "ppo (the default)",
            builtin("ppo"),
            &["total_timesteps=4096"],
            &["e7693ccfcc9c085e6a7d111c30e6f1924992060d7db2b379f1f8812e21530524"],
        ),
        (
            "ppo_deploy.toml",
            include_str!("../../../configs/ppo_deploy.toml").to_string(),
            &["total_timesteps=4096"],
            &["1c9027aeec21c4b941b6302b05ba6b347acd617d4c5cbf16ffacc72664860885"],
        ),
        (
            "sac",
            builtin("sac"),
            &["total_timesteps=1024", "sac.learning_starts=512"],
            &[
                "1b01911419523d84245d0fb61a98604e9a58abb179e80c21c98fe600f4421c6e",
                "a813169f1fad7c9918f498cc5a2b8295ea1d6908e161d14737b39741340b4f1f",
            ],
        ),
        (
            "td3",
            builtin("td3"),
            &["total_timesteps=1024", "td3.learning_starts=512"],
            &[
                "f0a6bcb2824cb245d1146416ddaa2a9dd2b678ccf53d1b24a56b14291481ba4b",
                "a50d965a257f46253bfd0ae38c8788eadfda8173730574ba3d01af73fc67a7a7",
            ],
        ),
    ];
    let hash_of = |text: &str, overrides: &[&str]| {
        let overrides: Vec<String> = (short.iter().chain(overrides))
            .map(|o| o.to_string())
            .collect();
        let config = TrainConfig::from_toml_str(text, &overrides).unwrap();
        let dir = tempfile::tempdir().unwrap();
        train(&config, dir.path(), |_| {}).unwrap();
        weights_sha256(dir.path())
    };
    let Some(kernel) = gemm_kernel() else {
        let (_, text, overrides, _) = &cases[0];
        assert_eq!(hash_of(text, overrides), hash_of(text, overrides));
        return;
    };
    let mut moved = Vec::new();
    for (name, text, overrides, hashes) in &cases {
        let pinned = hashes[if kernel == "avx512f" {
            0
        } else {
            hashes.len() - 1
        }];
        let found = hash_of(text, overrides);
        if found != pinned {
            moved.push(format!("{name}: {found}"));
        }
    }
    assert!(
        moved.is_empty(),
        "the weights moved (gemm kernel {kernel}):\n{}",
        moved.join("\n")
    );
}

/// The camera configs parse, their student settings checked against the teacher's
/// environment (a bad `[distill.env]` key is named before anything trains).
#[test]
fn the_camera_configs_parse_with_their_students_settings() {
    for (name, text) in [
        (
            "distill_grasp.toml",
            include_str!("../../../configs/distill_grasp.toml"),
        ),
        (
            "distill_deploy.toml",
            include_str!("../../../configs/distill_deploy.toml"),
        ),
    ] {
        let config = TrainConfig::from_toml_str(text, &[]).unwrap();
        let distill = config
            .distill
            .as_ref()
            .unwrap_or_else(|| panic!("{name}: no [distill]"));
        let camera = distill.env["camera"].as_table().unwrap();
        assert_eq!(camera["mode"].as_str(), Some("rgb+state"), "{name}");
        let bad = ["distill.env.camera.delay_steps=[2, 1]".to_string()];
        let err = TrainConfig::from_toml_str(text, &bad)
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("distill.env.camera.delay_steps"),
            "{name}: {err}"
        );
    }
}

/// The end-to-end camera config parses into a camera env with a PPO learner, refuses another
/// algorithm or a second way to the camera policy by key, and the state-policy loop refuses it.
#[test]
fn the_end_to_end_camera_config_parses_and_is_refused_where_it_cannot_run() {
    let text = include_str!("../../../configs/pixel_ppo_grasp.toml");
    let config = TrainConfig::from_toml_str(text, &[]).unwrap();
    assert!(config.pixel_ppo.is_some());
    let camera = config.env["camera"].as_table().unwrap();
    assert_eq!(camera["mode"].as_str(), Some("rgb+state"));
    let mut sac = config.clone();
    sac.algo = fairgrasp_rl::algo::AlgoConfig::default_for(Algo::Sac);
    let err = sac.validate().err().unwrap().to_string();
    assert!(
        err.contains("pixel_ppo") && err.contains("algo = \"ppo\""),
        "{err}"
    );
    let both = format!("{text}\n[distill]\nrounds = 2\n");
    let err = TrainConfig::from_toml_str(&both, &[])
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("not both"), "{err}");
    let dir = tempfile::tempdir().unwrap();
    let err = fairgrasp_rl::train::train(&config, dir.path(), |_| {})
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("run_pixel_ppo"), "{err}");
}
