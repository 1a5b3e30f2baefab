"""Every registered env as a Gymnasium env: the checkers of Gymnasium and SB3, settings, errors,
determinism and rendering."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import fairgrasp

ENV_IDS = [env_id for env_id, _ in fairgrasp.list_envs()]
ACTION_RANGE_ADVICE = (
    "we recommend using a symmetric and normalized space",  # Gymnasium's
    "We recommend you to use a symmetric and normalized Box action space",  # SB3's
)


def checked_warnings(check, env) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check(env)
    return [str(w.message) for w in caught]


def test_every_registered_env_is_registered_with_gymnasium():
    assert {"FaArmGrasp-v0", "FaArmPickPlace-v0", "FaArmSort-v0"} <= set(ENV_IDS)
    for env_id in ENV_IDS:
        assert f"fairgrasp/{env_id}" in gym.registry


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_and_sb3_checkers_pass_without_warnings(env_id):
    env = gym.make(f"fairgrasp/{env_id}")
    # The checkers want the bare env; gymnasium.make gave it the spec its render check needs.
    assert checked_warnings(gym_check_env, env.unwrapped) == []
    assert checked_warnings(sb3_check_env, env.unwrapped) == []
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_in_the_envs_own_units_the_only_warnings_are_the_action_range_advice(env_id):
    env = gym.make(f"fairgrasp/{env_id}", rescale_action=False)
    messages = checked_warnings(gym_check_env, env.unwrapped) + checked_warnings(
        sb3_check_env, env.unwrapped
    )
    assert all(any(a in m for a in ACTION_RANGE_ADVICE) for m in messages), messages
    low, high = env.action_space.low, env.action_space.high
    if env_id.startswith("FaArm"):
        # Joint-angle deltas of at most `control.max_joint_delta` (0.05 rad), then the gripper.
        np.testing.assert_allclose(high[:-1], 0.05, rtol=1e-6)
        assert high[-1] == 1.0
        assert messages, "a ±0.05 rad action space should draw the advice"
    assert np.all(low == -high)


def test_settings_are_the_toml_keys_nested_or_dotted():
    nested = fairgrasp.FairgraspEnv(control={"action_mode": "cartesian"}, task={"max_episode_steps": 80})
    dotted = fairgrasp.FairgraspEnv(**{"control.action_mode": "cartesian", "task.max_episode_steps": 80})
    assert nested.config_toml() == dotted.config_toml()
    assert 'action_mode = "cartesian"' in nested.config_toml()
    assert nested.action_space.shape == (5,)  # dx, dy, dz, dyaw, gripper
    assert fairgrasp.FairgraspEnv().action_space.shape == (7,)
    assert fairgrasp.env_config(
        "FaArmGrasp-v0", control={"action_mode": "cartesian"}, task={"max_episode_steps": 80}
    ) == nested.config_toml()


def test_bad_settings_raise_config_error_naming_the_key():
    with pytest.raises(fairgrasp.ConfigError, match="action_mod"):
        gym.make("fairgrasp/FaArmGrasp-v0", control={"action_mod": "joint"})
    with pytest.raises(fairgrasp.ConfigError, match="control.max_joint_delta"):
        fairgrasp.FairgraspEnv(**{"control.max_joint_delta": -1.0})
    with pytest.raises(fairgrasp.ConfigError, match="unknown environment `NoSuchEnv-v0`"):
        fairgrasp.FairgraspEnv("NoSuchEnv-v0")
    with pytest.raises(fairgrasp.ConfigError, match="task.max_episode_steps"):
        fairgrasp.FairgraspEnv(task={"max_episode_steps": object()})
    with pytest.raises(fairgrasp.ConfigError, match="Pendulum-v1 has no render modes"):
        fairgrasp.FairgraspEnv("Pendulum-v1", render_mode="rgb_array")
    # ConfigError is a ValueError for code that catches those.
    assert issubclass(fairgrasp.ConfigError, ValueError)


def test_bad_actions_raise_action_error_and_leave_the_episode_unchanged():
    env = fairgrasp.FairgraspEnv()
    env.reset(seed=3)
    twin = fairgrasp.FairgraspEnv()
    twin.reset(seed=3)
    for bad, pattern in [
        (np.full(7, np.nan, dtype=np.float32), "NaN"),
        (np.array([0, 0, 0, 0, 0, 0, np.inf]), "finite|inf"),
        (np.zeros(6, dtype=np.float32), r"expected shape \[7\]"),
        (np.zeros((1, 7), dtype=np.float32), r"got shape \[1, 7\]"),
        ("not an action", "float32"),
    ]:
        with pytest.raises(fairgrasp.ActionError, match=pattern):
            env.step(bad)
    action = np.linspace(-1, 1, 7, dtype=np.float32)
    assert np.array_equal(env.step(action)[0], twin.step(action)[0])


def test_misuse_raises_instead_of_crashing():
    env = fairgrasp.FairgraspEnv()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(7, dtype=np.float32))
    env.close()
    with pytest.raises(RuntimeError, match="closed"):
        env.reset(seed=0)
    env.close()  # twice is fine


def test_the_same_seed_gives_the_same_trajectory_and_lists_and_float64_are_accepted():
    def rollout(seed: int) -> list[np.ndarray]:
        env = fairgrasp.FairgraspEnv(randomization={"enabled": True})
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(0)
        out = [obs]
        for _ in range(30):
            obs, *_ = env.step(rng.uniform(-1, 1, 7))  # float64: converted
            out.append(obs)
        return out

    a, b, c = rollout(5), rollout(5), rollout(6)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.array_equal(a[0], c[0])
    env = fairgrasp.FairgraspEnv()
    env.reset(seed=0)
    assert env.step([0.0] * 6 + [1.0])[0].dtype == np.float32


def test_unseeded_envs_play_different_episodes():
    first = [fairgrasp.FairgraspEnv().reset()[0] for _ in range(2)]
    assert not np.array_equal(first[0], first[1])


def test_observations_stay_inside_the_finite_observation_space():
    env = gym.make("fairgrasp/FaArmPickPlace-v0")
    assert np.all(np.isfinite(env.observation_space.low))
    obs, _ = env.reset(seed=1)
    for _ in range(200):
        assert env.observation_space.contains(obs)
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            obs, _ = env.reset()


def test_rgb_and_depth_frames_come_back_as_arrays():
    size = {"width": 64, "height": 48}
    rgb = fairgrasp.FairgraspEnv(render_mode="rgb_array", render=size)
    rgb.reset(seed=0)
    frame = rgb.render()
    assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8
    assert frame.std() > 5, "a flat image shows no scene"
    depth = fairgrasp.FairgraspEnv(render_mode="depth_array", render=size)
    depth.reset(seed=0)
    d = depth.render()
    assert d.shape == (48, 64) and d.dtype == np.float32
    assert 0.05 < d.min() < d.max()
    seg = fairgrasp.FairgraspEnv(render_mode="segmentation_array", render=size)
    seg.reset(seed=0)
    ids = seg.render()
    assert ids.dtype == np.uint16 and 32 in np.unique(ids)  # the cube is in view
    assert fairgrasp.FairgraspEnv().render() is None


def test_infos_carry_success_reward_terms_and_the_tasks_values():
    env = fairgrasp.FairgraspEnv()
    _, info = env.reset(seed=0)
    _, reward, _, _, info = env.step(np.zeros(7, dtype=np.float32))
    assert info["is_success"] is False
    assert info["elapsed_steps"] == 1
    assert set(info["reward_terms"]) >= {"approach", "grasp", "time"}
    assert abs(sum(info["reward_terms"].values()) - reward) < 1e-5
    assert "grasped" in info and "lift" in info
    assert "privileged" not in info
    # With [readings] privileged: the true state's observation and the speed scale, for a critic.
    env = fairgrasp.FairgraspEnv(readings={"enabled": True, "privileged": True})
    obs, info = env.reset(seed=0)
    assert info["privileged"].dtype == np.float32
    assert info["privileged"].shape == (obs.shape[0] + 1,) and info["privileged"][-1] == 1.0
