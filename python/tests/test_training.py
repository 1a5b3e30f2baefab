"""`fairgrasp.train` and `fairgrasp.evaluate`: the native trainer driven from Python."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

import pytest

import fairgrasp

QUICK = {
    "total_timesteps": 4096,
    "n_envs": 2,
    "threads": 1,
    "checkpoint_freq": 2048,
    "eval": {"freq": 2048, "episodes": 2},
    "ppo": {"n_steps": 256, "batch_size": 128, "n_epochs": 2},
}


def test_train_reports_progress_writes_the_run_and_evaluates(tmp_path):
    seen = []
    summary = fairgrasp.train(
        env_id="PointReach-v0", run_dir=tmp_path / "run", callback=seen.append, **QUICK
    )
    assert summary["num_timesteps"] >= 4096 and summary["algo"] == "ppo"
    assert [p["num_timesteps"] for p in seen] == sorted(p["num_timesteps"] for p in seen)
    assert seen[-1]["eval_count"] == 2 and seen[-1]["last_eval"]["episodes"] == 2
    assert (tmp_path / "run" / "best" / "model.json").is_file()
    result = fairgrasp.evaluate(tmp_path / "run", episodes=3, seed=5)
    assert result["episodes"] == 3 and -60 < result["mean_return"] < 0
    policy = fairgrasp.Policy.load(tmp_path / "run" / "final")
    assert policy.env_id == "PointReach-v0" and policy.obs_dim == 6


def test_the_same_seed_trains_the_same_weights(tmp_path):
    for name in ("a", "b"):
        fairgrasp.train(env_id="PointReach-v0", run_dir=tmp_path / name, seed=3, **QUICK)
    a = (tmp_path / "a" / "final" / "model.safetensors").read_bytes()
    b = (tmp_path / "b" / "final" / "model.safetensors").read_bytes()
    assert a == b


def test_a_callback_returning_false_stops_the_run_and_the_model_is_saved(tmp_path):
    summary = fairgrasp.train(
        env_id="PointReach-v0",
        run_dir=tmp_path / "run",
        callback=lambda p: p["num_timesteps"] < 2048,
        **{**QUICK, "total_timesteps": 100_000},
    )
    # 512 steps per iteration: stopped at 2048, where the first checkpoint was written.
    assert summary["stopped"] is True and summary["num_timesteps"] == 2048
    assert (tmp_path / "run" / "final" / "model.safetensors").is_file()
    # An exception in the callback stops the run and reaches the caller.
    with pytest.raises(ZeroDivisionError):
        fairgrasp.train(
            env_id="PointReach-v0", run_dir=tmp_path / "run2", callback=lambda p: 1 / 0, **QUICK
        )
    # And the run continues from its checkpoint.
    resumed = fairgrasp.train(run_dir=tmp_path / "run", resume=True, total_timesteps=4096)
    assert resumed["resumed_from"] == 2048 and resumed["num_timesteps"] == 4096


def test_training_releases_the_gil(tmp_path):
    done = threading.Event()
    thread = threading.Thread(
        target=lambda: (
            # Eight times QUICK's steps: long enough (about 1.5 s on a 2-core host) for the
            # spinning below to mean something on a fast host too.
            fairgrasp.train(
                env_id="PointReach-v0", run_dir=tmp_path / "run", **{**QUICK, "total_timesteps": 32_768}
            ),
            done.set(),
        )
    )
    iterations = 0
    started = time.perf_counter()
    thread.start()
    while not done.is_set():
        iterations += 1
    thread.join()
    # With the GIL held for the whole call, this thread could not count while training ran.
    assert iterations > 100_000, (iterations, time.perf_counter() - started)


def test_bad_training_settings_raise_config_error_naming_the_key(tmp_path):
    with pytest.raises(fairgrasp.ConfigError, match="ppo.learning_rat|learning_rat"):
        fairgrasp.train(run_dir=tmp_path / "x", **{"ppo.learning_rat": 1e-4})
    with pytest.raises(fairgrasp.ConfigError, match="unknown environment"):
        fairgrasp.train(env_id="Nope-v0", run_dir=tmp_path / "y")
    (tmp_path / "z").mkdir()
    (tmp_path / "z" / "config.toml").write_text("")
    with pytest.raises(fairgrasp.ConfigError, match="already holds a training run"):
        fairgrasp.train(env_id="PointReach-v0", run_dir=tmp_path / "z")
    assert 'env_id = "FaArmGrasp-v0"' in fairgrasp.default_train_config()
    assert 'algo = "sac"' in fairgrasp.default_train_config(algo="sac")
    with pytest.raises(fairgrasp.ConfigError, match="unknown algorithm `dqn` \\(one of ppo, sac, td3\\)"):
        fairgrasp.default_train_config(algo="dqn")
    with pytest.raises(fairgrasp.ConfigError, match="unknown algorithm `dqn`"):
        fairgrasp.train(algo="dqn", run_dir=tmp_path / "w")


def test_importing_fairgrasp_runs_the_networks_on_one_thread_unless_told_otherwise():
    def seen(env):
        code = "import os, fairgrasp; print(os.environ['RAYON_NUM_THREADS'])"
        done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
        return done.stdout.strip()

    unset = {k: v for k, v in os.environ.items() if k != "RAYON_NUM_THREADS"}
    assert seen(unset) == "1"
    assert seen({**unset, "RAYON_NUM_THREADS": "3"}) == "3"
