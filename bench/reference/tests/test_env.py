"""Tests of the PyBullet reference env: the Gymnasium contract, seeding, refusal of bad actions,
and that the task can be solved (a scripted pick succeeds through `step()`).

    bench/.venv/bin/python -m unittest discover -s bench/reference/tests
"""

import sys
import unittest
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fa_arm_grasp_ref import ENV_ID, FaArmGraspRefEnv, scripted_pick  # noqa: E402


class ReferenceEnvTest(unittest.TestCase):
    def setUp(self):
        self.env = FaArmGraspRefEnv()

    def tearDown(self):
        self.env.close()

    def test_passes_gymnasium_env_checker_without_warnings(self):
        import gymnasium as gym
        from gymnasium.utils.env_checker import check_env

        env = gym.make(ENV_ID, render_mode="rgb_array")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped)
        env.close()
        self.assertEqual([str(w.message) for w in caught], [])

    def test_renders_rgb_frames(self):
        env = FaArmGraspRefEnv(render_mode="rgb_array")
        env.reset(seed=0)
        frame = env.render()
        env.close()
        self.assertEqual(frame.shape, (240, 320, 3))
        self.assertGreater(frame.std(), 5.0)  # a picture, not a blank

    def test_spaces_follow_the_design(self):
        self.assertEqual(self.env.observation_space.shape, (23,))
        np.testing.assert_allclose(self.env.action_space.high, [0.1] * 6 + [1.0])
        obs, info = self.env.reset(seed=3)
        self.assertIn(obs, self.env.observation_space)
        # The arm starts at home, the cube rests on the table 40 x 40 cm around (0.5, 0).
        np.testing.assert_allclose(obs[:6], self.env.scene.settings.home, atol=1e-3)
        self.assertLessEqual(abs(obs[12] - 0.5), 0.2 + 1e-3)
        self.assertLessEqual(abs(obs[13]), 0.2 + 1e-3)
        self.assertAlmostEqual(info["lift"], 0.0, delta=2e-3)
        self.assertAlmostEqual(obs[22], 0.09, delta=1e-3)  # gripper open

    def test_same_seed_same_trajectory(self):
        def rollout(seed):
            obs, _ = self.env.reset(seed=seed)
            rng = np.random.default_rng(7)
            out = [obs]
            for _ in range(30):
                action = rng.uniform(self.env.action_space.low, self.env.action_space.high)
                out.append(self.env.step(action.astype(np.float32))[0])
            return np.array(out)

        a, b, c = rollout(11), rollout(11), rollout(12)
        np.testing.assert_array_equal(a, b)
        self.assertFalse(np.allclose(a[0, 12:15], c[0, 12:15]))

    def test_bad_actions_raise_and_change_nothing(self):
        obs, _ = self.env.reset(seed=0)
        with self.assertRaisesRegex(ValueError, "expected 7 values"):
            self.env.step(np.zeros(6, dtype=np.float32))
        with self.assertRaisesRegex(ValueError, "value 2 is nan"):
            self.env.step(np.array([0, 0, np.nan, 0, 0, 0, 1], dtype=np.float32))
        self.assertEqual(self.env.steps, 0)
        np.testing.assert_allclose(self.env.arm_target, self.env.scene.settings.home)

    def test_step_before_reset_or_after_the_end_raises(self):
        with self.assertRaisesRegex(RuntimeError, "reset"):
            self.env.step(self.env.action_space.sample())
        self.env.reset(seed=0)
        truncated = False
        while not truncated:
            _, _, terminated, truncated, _ = self.env.step(np.zeros(7, dtype=np.float32))
            self.assertFalse(terminated)
        with self.assertRaisesRegex(RuntimeError, "reset"):
            self.env.step(np.zeros(7, dtype=np.float32))

    def test_scripted_pick_succeeds(self):
        for seed in range(5):
            success, steps = scripted_pick(self.env, seed)
            self.assertTrue(success, f"seed {seed}: no success after {steps} steps")
            self.assertLess(steps, self.env.task["max_episode_steps"])

    def test_holding_still_never_succeeds_and_pays_only_time(self):
        self.env.reset(seed=1)
        action = np.array([0, 0, 0, 0, 0, 0, -1], dtype=np.float32)  # close on nothing
        for _ in range(20):
            _, reward, terminated, _, info = self.env.step(action)
            self.assertFalse(terminated)
            self.assertFalse(info["grasped"])
            self.assertLess(reward, 0.01)


if __name__ == "__main__":
    unittest.main()
