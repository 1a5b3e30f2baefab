"""`fairgrasp.make_vec_env`: the native SB3 VecEnv, and the Gymnasium VectorEnv face."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

import fairgrasp


def test_reset_and_step_batches_with_terminal_observations_and_episode_stats():
    venv = fairgrasp.make_vec_env("FaArmGrasp-v0", 4, seed=10, task={"max_episode_steps": 20})
    obs = venv.reset()
    assert obs.shape == (4, 40) and obs.dtype == np.float32
    ended = 0
    for step in range(20):
        actions = np.random.default_rng(step).uniform(-1, 1, (4, 7)).astype(np.float32)
        obs, rewards, dones, infos = venv.step(actions)
        assert rewards.shape == (4,) and rewards.dtype == np.float32 and dones.dtype == bool
        assert len(infos) == 4 and all("is_success" in i for i in infos)
        for i in np.flatnonzero(dones):
            ended += 1
            info = infos[i]
            assert info["terminal_observation"].shape == (40,)
            assert not np.array_equal(info["terminal_observation"], obs[i])  # row is the new episode
            assert info["TimeLimit.truncated"] is True  # 20-step limit, no success with random actions
            assert info["episode"]["l"] == 20
            assert venv.reset_infos[i]["elapsed_steps"] == 0
    assert ended == 4
    venv.close()


def test_seeds_match_single_envs_and_threads_do_not_change_results():
    def rollout(threads: int) -> np.ndarray:
        venv = fairgrasp.make_vec_env("FaArmGrasp-v0", 3, threads=threads)
        venv.seed(100)
        out = [venv.reset()]
        for k in range(15):
            out.append(venv.step(np.full((3, 7), 0.3 * np.sin(k), dtype=np.float32))[0])
        return np.stack(out)

    one, two = rollout(1), rollout(2)
    assert np.array_equal(one, two)
    for i in range(3):
        single, _ = fairgrasp.FairgraspEnv().reset(seed=100 + i)
        assert np.array_equal(one[0, i], single)
    # Arbitrary seeds per env go through reset_env.
    venv = fairgrasp.make_vec_env("FaArmGrasp-v0", 2)
    venv._seeds = [7, 3]
    obs = venv.reset()
    assert np.array_equal(obs[1], fairgrasp.FairgraspEnv().reset(seed=3)[0])


def test_unseeded_envs_do_not_play_the_same_episodes():
    obs = fairgrasp.make_vec_env("FaArmGrasp-v0", 4).reset()
    assert len({row.tobytes() for row in obs}) == 4


def test_attributes_methods_and_errors_as_sb3_expects():
    venv = fairgrasp.make_vec_env("FaArmGrasp-v0", 2, render_mode="rgb_array", render={"width": 32, "height": 24})
    venv.reset()
    assert venv.get_attr("render_mode") == ["rgb_array", "rgb_array"]
    assert venv.get_attr("spec")[0].id == "fairgrasp/FaArmGrasp-v0"
    venv.set_attr("difficulty", 3, indices=[1])
    assert venv.get_attr("difficulty", indices=1) == [3]
    with pytest.raises(AttributeError, match="difficulty"):
        venv.get_attr("difficulty", indices=0)
    frames = venv.env_method("render")
    assert [f.shape for f in frames] == [(24, 32, 3)] * 2
    assert venv.render().shape[2] == 3  # SB3 tiles the frames
    assert venv.env_is_wrapped(VecMonitor) == [False, False]
    with pytest.raises(AttributeError, match="no method 'fly'"):
        venv.env_method("fly")
    with pytest.raises(fairgrasp.ActionError, match=r"expected shape \[2, 7\]"):
        venv.step(np.zeros((2, 6), dtype=np.float32))
    bad = np.zeros((2, 7), dtype=np.float32)
    bad[1, 3] = np.nan
    with pytest.raises(fairgrasp.ActionError, match="NaN"):
        venv.step(bad)
    venv.step(np.zeros((2, 7), dtype=np.float32))  # still usable


def test_sb3_ppo_trains_on_it_with_sb3_wrappers():
    venv = VecNormalize(VecMonitor(fairgrasp.make_vec_env("FaArmGrasp-v0", 8, seed=0)))
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=128, n_epochs=2, seed=0, device="cpu")
    model.learn(total_timesteps=1024)
    assert model.num_timesteps == 1024
    # 128 steps per env and 100-step episodes: every env finished one, logged through VecMonitor.
    assert len(model.ep_info_buffer) >= 8 and "r" in model.ep_info_buffer[0]
    action, _ = model.predict(venv.reset(), deterministic=True)
    assert action.shape == (8, 7)


def test_steps_release_the_gil():
    # 64 envs on one Rust thread: each step holds the call for several milliseconds. While a
    # Python thread steps them, this thread must keep running.
    venv = fairgrasp.make_vec_env("FaArmGrasp-v0", 64, threads=1, seed=0)
    venv.reset()
    actions = np.zeros((64, 7), dtype=np.float32)
    done = threading.Event()
    calls = []

    def stepper():
        started = time.perf_counter()
        while time.perf_counter() - started < 1.5:
            venv.step(actions)
            calls.append(1)
        done.set()

    thread = threading.Thread(target=stepper)
    iterations = 0
    thread.start()
    while not done.is_set():
        iterations += 1
    thread.join()
    assert len(calls) >= 3
    # Holding the GIL through each step would leave this loop a sliver of the time; with it
    # released the loop runs through every step (measured: millions of iterations).
    assert iterations > 100_000, iterations


def test_gymnasium_vector_env_face_resets_in_the_same_step():
    envs = fairgrasp.FairgraspVectorEnv("FaArmGrasp-v0", 3, task={"max_episode_steps": 5})
    obs, infos = envs.reset(seed=1)
    assert obs.shape == (3, 40) and envs.single_action_space.shape == (7,)
    assert np.array_equal(obs[2], fairgrasp.FairgraspEnv(task={"max_episode_steps": 5}).reset(seed=3)[0])
    for _ in range(5):
        obs, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
    assert truncated.all() and rewards.dtype == np.float64
    assert infos["_final_obs"].all()
    assert infos["final_obs"][0].shape == (40,)
    assert np.array_equal(infos["final_info"]["elapsed_steps"], [5, 5, 5])
    assert np.array_equal(infos["elapsed_steps"], [0, 0, 0])  # the new episodes' reset infos
    envs.close()
