//! A short training run writes what SB3 users expect, readable by an event-file reader.

use fairgrasp_rl::logger::read_scalars;
use fairgrasp_rl::train::{TrainConfig, train_ppo};

#[test]
fn a_short_run_writes_config_logs_best_model_and_checkpoints() {
    let dir = tempfile::tempdir().unwrap();
    let config = TrainConfig::from_toml_str(
        "total_timesteps = 1024\nn_envs = 2\nthreads = 1\ncheckpoint_freq = 512\n\
         [eval]\nfreq = 512\nepisodes = 1\n\
         [ppo]\nn_steps = 128\nbatch_size = 64\nn_epochs = 2\n\
         [env.task]\nmax_episode_steps = 20\n",
        &["env.reward.kind=staged".into()],
    )
    .unwrap();
    let summary = train_ppo(&config, dir.path(), |_| {}).unwrap();
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
    assert!(checkpoint.join("optimizer.safetensors").is_file());
    // The effective configuration is saved and loads back equal.
    let saved = std::fs::read_to_string(dir.path().join("config.toml")).unwrap();
    assert_eq!(TrainConfig::from_toml_str(&saved, &[]).unwrap(), config);

    let tb = std::fs::read_dir(dir.path().join("tb"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let scalars = read_scalars(&tb).unwrap();
    for tag in [
        "rollout/ep_rew_mean",
        "rollout/success_rate",
        "train/policy_gradient_loss",
        "train/value_loss",
        "train/entropy_loss",
        "train/approx_kl",
        "train/clip_fraction",
        "train/explained_variance",
        "time/fps",
        "eval/success_rate",
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

#[test]
fn training_config_errors_name_the_key() {
    for (text, key) in [
        ("n_envs = 0\n", "n_envs"),
        ("[ppo]\nbatch_size = 0\n", "ppo.batch_size"),
        ("[ppo]\nlearning_rat = 0.1\n", "learning_rat"),
        (
            "[env.task]\nmax_joint_delta = 9.0\n",
            "task.max_joint_delta",
        ),
    ] {
        let err = TrainConfig::from_toml_str(text, &[])
            .err()
            .unwrap_or_else(|| panic!("{text} accepted"))
            .to_string();
        assert!(err.contains(key), "{text}: {err}");
    }
}
