"""`fairgrasp.Policy`: models trained by `fairgrasp train`, acting from Python exactly as the CLI."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from conftest import run_cli

import fairgrasp


def test_predict_gives_the_actions_of_fairgrasp_eval(tmp_path, fairgrasp_bin, trained_model):
    trace = tmp_path / "trace.jsonl"
    run_cli(
        fairgrasp_bin, "eval", "--model", str(trained_model), "--episodes", "2", "--trace", str(trace)
    )
    rows = [json.loads(line) for line in trace.read_text().splitlines()]
    assert len(rows) > 20
    policy = fairgrasp.Policy.load(trained_model)
    obs = np.array([r["obs"] for r in rows], dtype=np.float32)
    expected = np.array([r["action"] for r in rows], dtype=np.float32)
    one_by_one = np.stack([policy.predict(o, deterministic=True)[0] for o in obs])
    assert np.array_equal(one_by_one, expected)
    batched, state = policy.predict(obs, deterministic=True)
    assert state is None and batched.shape == expected.shape
    np.testing.assert_allclose(batched, expected, atol=1e-5)


def test_a_loaded_policy_grasps_in_the_gymnasium_env_it_names(trained_model):
    policy = fairgrasp.Policy.load(trained_model)
    assert policy.env_id == "FaArmGrasp-v0" and policy.algo == "ppo"
    env = gym.make(f"fairgrasp/{policy.env_id}", **policy.env_config)
    successes = 0
    for episode in range(3):
        obs, _ = env.reset(seed=2_000_000_000 + episode)
        while True:
            action, _ = policy.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = env.step(np.clip(action, -1, 1))
            if terminated or truncated:
                successes += info["is_success"]
                break
    assert successes >= 2
    result = fairgrasp.evaluate(policy, episodes=3)
    assert result["episodes"] == 3 and result["success_rate"] >= 2 / 3


def test_stochastic_actions_follow_the_policys_seed(trained_model):
    policy = fairgrasp.Policy.load(trained_model)
    obs = np.zeros(policy.obs_dim, dtype=np.float32)
    policy.set_seed(1)
    a = policy.predict(obs)[0]
    policy.set_seed(1)
    assert np.array_equal(a, policy.predict(obs)[0])
    assert not np.array_equal(a, policy.predict(obs)[0])


def test_bad_models_and_observations_raise_clear_errors(tmp_path, trained_model):
    with pytest.raises(fairgrasp.ModelError, match="nowhere"):
        fairgrasp.Policy.load(tmp_path / "nowhere")
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "model.json").write_text((trained_model / "model.json").read_text())
    (broken / "model.safetensors").write_bytes(b"\x00" * 16)
    with pytest.raises(fairgrasp.ModelError, match="model.safetensors"):
        fairgrasp.Policy.load(broken)
    policy = fairgrasp.Policy.load(trained_model)
    n = policy.obs_dim
    with pytest.raises(ValueError, match=rf"expected shape \({n},\) or \(n, {n}\)"):
        policy.predict(np.zeros(n - 1, dtype=np.float32))
    bad = np.zeros(n, dtype=np.float32)
    bad[5] = np.nan
    with pytest.raises(RuntimeError, match="value 5 is NaN"):
        policy.predict(bad)


def test_a_camera_policy_predicts_on_dict_observations_as_fairgrasp_eval(camera_model):
    policy = fairgrasp.Policy.load(camera_model)
    assert policy.image_views == [("scene_rgb", 24, 24, 3)]
    env = gym.make(f"fairgrasp/{policy.env_id}", **policy.env_config)
    seed = 2_000_000_000
    observations, total = [], 0.0
    for episode in range(2):
        obs, _ = env.reset(seed=seed + episode)
        while True:
            observations.append(obs)
            action, _ = policy.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(np.clip(action, -1, 1))
            total += reward
            if terminated or truncated:
                break
    # The same episodes through Rust's evaluation of the saved model: the same return.
    result = fairgrasp.evaluate(policy, episodes=2, seed=seed)
    assert abs(result["mean_return"] - total / 2) < 1e-3 * max(1.0, abs(total))
    # A batch of Dict observations gives each one's action.
    batch = {key: np.stack([o[key] for o in observations[:5]]) for key in observations[0]}
    actions, _ = policy.predict(batch, deterministic=True)
    singles = np.stack([policy.predict(o, deterministic=True)[0] for o in observations[:5]])
    assert actions.shape == singles.shape == (5, policy.act_dim)
    np.testing.assert_allclose(actions, singles, atol=1e-5)
    with pytest.raises(ValueError, match="Dict observation"):
        policy.predict(observations[0]["state"])
    with pytest.raises(ValueError, match="scene_rgb"):
        policy.predict({"state": observations[0]["state"], "scene_rgb": np.zeros((8, 8, 3), np.uint8)})
