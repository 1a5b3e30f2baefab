"""Camera observations from Python: ``obs_mode`` gives a ``Dict`` of the arm's readings and
uint8 images, which Gymnasium's and SB3's checkers accept and SB3's ``MultiInputPolicy`` learns
from."""

from __future__ import annotations

import os
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3 import PPO
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.vec_env import VecMonitor

import fairgrasp

SMALL = {"camera": {"width": 48, "height": 48}}


@pytest.mark.parametrize(
    ("obs_mode", "key", "channels"),
    [("rgb+state", "scene_rgb", 3), ("depth+state", "scene_depth", 1), ("rgbd+state", "scene_rgbd", 4)],
)
def test_pixel_modes_are_dict_spaces_that_both_checkers_accept(obs_mode, key, channels):
    env = gym.make("fairgrasp/FaArmGrasp-v0", obs_mode=obs_mode, **SMALL)
    space = env.observation_space
    assert isinstance(space, spaces.Dict)
    assert set(space.spaces) == {"state", key}
    assert space[key].shape == (48, 48, channels) and space[key].dtype == np.uint8
    assert space["state"].dtype == np.float32
    gym_check_env(env.unwrapped)
    sb3_check_env(env.unwrapped)
    obs, _ = env.reset(seed=3)
    assert space.contains(obs)
    env.close()


def test_the_state_is_the_arms_own_and_the_camera_shows_where_the_cube_is():
    env = fairgrasp.make("FaArmGrasp-v0", obs_mode="rgb+state", camera={"wrist": {"enabled": True}})
    assert set(env.observation_space.spaces) == {"state", "scene_rgb", "wrist_rgb"}
    a, info_a = env.reset(seed=1)
    b, info_b = env.reset(seed=2)
    # The arm starts at home whatever the seed: only the images (and the critic's privileged
    # state) know where the cube is.
    np.testing.assert_array_equal(a["state"], b["state"])
    assert not np.array_equal(a["scene_rgb"], b["scene_rgb"])
    assert not np.array_equal(info_a["privileged"], info_b["privileged"])
    obs, *_ = env.step(np.ones(7, dtype=np.float32))
    assert not np.array_equal(obs["wrist_rgb"], b["wrist_rgb"]), "the wrist camera moved"


def test_an_env_without_cameras_refuses_an_obs_mode():
    with pytest.raises(fairgrasp.ConfigError, match="obs_mode"):
        fairgrasp.make("Pendulum-v1", obs_mode="rgb+state")
    with pytest.raises(fairgrasp.ConfigError, match="camera.mode"):
        fairgrasp.make("FaArmGrasp-v0", obs_mode="rgb")


def test_sb3_multi_input_ppo_runs_on_the_native_vector_env():
    venv = VecMonitor(
        fairgrasp.make_vec_env(
            "FaArmGrasp-v0", 2, seed=0, obs_mode="rgb+state", task={"max_episode_steps": 20}, **SMALL
        )
    )
    obs = venv.reset()
    assert obs["state"].shape == (2, 29) and obs["scene_rgb"].shape == (2, 48, 48, 3)
    model = PPO("MultiInputPolicy", venv, n_steps=32, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=64)
    assert model.num_timesteps == 64
    assert len(model.ep_info_buffer) >= 2, "20-step episodes end within 32 steps"
    action, _ = model.predict(venv.reset(), deterministic=True)
    assert action.shape == (2, 7)


def test_terminal_observations_carry_their_images():
    venv = fairgrasp.make_vec_env(
        "FaArmGrasp-v0", 2, seed=0, obs_mode="depth+state", task={"max_episode_steps": 2}, **SMALL
    )
    venv.reset()
    actions = np.zeros((2, 7), dtype=np.float32)
    venv.step(actions)
    obs, _, dones, infos = venv.step(actions)
    assert dones.all()
    final = infos[0]["terminal_observation"]
    assert final["scene_depth"].shape == (48, 48, 1) and final["state"].shape == (29,)
    assert not np.array_equal(final["state"], obs["state"][0])
    gvenv = fairgrasp.FairgraspVectorEnv("FaArmGrasp-v0", 2, obs_mode="depth+state", **SMALL)
    assert gvenv.observation_space["scene_depth"].shape == (2, 48, 48, 1)
    gobs, _ = gvenv.reset(seed=5)
    assert gvenv.observation_space.contains(gobs)


def test_an_unknown_image_kernel_is_refused_at_import_by_name():
    def import_with(kernel):
        env = dict(os.environ, FAIRGRASP_IMAGE_KERNEL=kernel)
        return subprocess.run(
            [sys.executable, "-c", "import fairgrasp"], env=env, capture_output=True, text=True, timeout=120
        )

    done = import_with("avx9")
    assert done.returncode != 0
    assert "FAIRGRASP_IMAGE_KERNEL=avx9" in done.stderr and "expected avx2 or gemm" in done.stderr
    done = import_with("gemm")
    assert done.returncode == 0, done.stderr
