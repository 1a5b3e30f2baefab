"""`FaArmGraspRef-v0`: the design document's grasp environment in PyBullet, as a gymnasium.Env.

The task definition matches fairgrasp's `FaArmGrasp-v0` with the `seed23` observation, joint-delta
actions and the `hybrid` (or `sparse`) reward: the same figures, read from `configs/env.toml`.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .scene import GraspScene, SceneSettings, load_env_config


class FaArmGraspRefEnv(gym.Env):
    """Pick up the cube with the FR5 (PyBullet reference implementation).

    Observation (23, float32, base frame): joint angles (6), TCP position (3), TCP roll-pitch-yaw
    (3), cube position (3), cube quaternion xyzw (4), TCP linear velocity (3), gripper opening (1).

    Action (7, float32): six joint-angle deltas in [-max_joint_delta, max_joint_delta] and a
    gripper command in [-1, 1] (> 0 open, otherwise close). Deltas accumulate on the joint
    targets, which are clamped to the joint limits and may lead the measured angles by at most
    three steps' worth. Actions outside the box are clipped; NaN or wrong-length actions raise.

    Success: gripper commanded closed with both pads touching the cube and the fingers stopped by
    it, cube lifted more than 5 cm above its resting height and within 8 cm of the TCP, for 10
    consecutive control steps. The episode terminates on success or when the cube leaves the
    table, and is truncated after `max_episode_steps` control steps.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(
        self,
        render_mode: str | None = None,
        reward_type: str = "hybrid",
        max_joint_delta: float = 0.1,
        config_path: str | Path | None = None,
    ):
        super().__init__()
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode {render_mode!r} is not one of None, 'rgb_array'")
        if reward_type not in ("hybrid", "sparse"):
            raise ValueError(f"reward_type {reward_type!r} is not 'hybrid' or 'sparse'")
        if not (np.isfinite(max_joint_delta) and max_joint_delta > 0):
            raise ValueError(f"max_joint_delta must be positive, got {max_joint_delta}")
        config = load_env_config(Path(config_path) if config_path else None)
        self.task = config["task"]
        self.weights = config["reward"]
        self.render_mode = render_mode
        self.reward_type = reward_type
        self.max_joint_delta = float(max_joint_delta)
        self.scene = GraspScene(SceneSettings.from_config(config))
        self.metadata = {
            **self.metadata,
            "render_fps": round(1 / (self.scene.settings.dt * self.scene.settings.substeps)),
        }

        d = self.max_joint_delta
        self.action_space = spaces.Box(
            low=np.array([-d] * 6 + [-1.0], dtype=np.float32),
            high=np.array([d] * 6 + [1.0], dtype=np.float32),
            dtype=np.float32,
        )
        # The design's space is unbounded; ±10 (m, rad, m/s) holds every reachable state and
        # keeps Gymnasium's checker from warning about infinite bounds. Values are unchanged.
        self.observation_space = spaces.Box(-10.0, 10.0, shape=(23,), dtype=np.float32)
        self._episode_open = False

    # ── Gymnasium API ──────────────────────────────────────────────────────

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.scene.reset(self.np_random)
        self.arm_target = np.array(self.scene.settings.home, dtype=np.float64)
        self.steps = 0
        self.success_streak = 0
        self.grasp_paid = False
        status = self._status()
        self.previous_distance = status["ee_object_distance"]
        self._episode_open = True
        return self._observe(), self._info(status, success=False)

    def step(self, action):
        if not self._episode_open:
            raise RuntimeError("call reset() before step() (the episode has ended or not begun)")
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (7,):
            raise ValueError(
                f"expected 7 values (6 joint-angle deltas and a gripper command), got {a.size}"
            )
        if not np.all(np.isfinite(a)):
            i = int(np.flatnonzero(~np.isfinite(a))[0])
            raise ValueError(f"action value {i} is {a[i]}; actions must be finite")
        a = np.clip(a, self.action_space.low, self.action_space.high)

        scene = self.scene
        q = scene.arm_positions()
        lead = 3 * self.max_joint_delta
        target = np.clip(self.arm_target + a[:6], q - lead, q + lead)
        self.arm_target = np.clip(target, scene.arm_limits[:, 0], scene.arm_limits[:, 1])
        scene.set_arm_targets(self.arm_target)
        scene.set_gripper_open(a[6] > 0)
        scene.step_control()

        self.steps += 1
        status = self._status()
        satisfied = (
            status["grasped"]
            and status["lift"] > self.task["success_min_lift"]
            and status["ee_object_distance"] < self.task["success_max_offset"]
        )
        self.success_streak = self.success_streak + 1 if satisfied else 0
        success = self.success_streak >= self.task["success_hold_steps"]
        off_table = scene.object_off_table()
        reward = self._reward(status, success, off_table)
        terminated = success or off_table
        truncated = not terminated and self.steps >= self.task["max_episode_steps"]
        if terminated or truncated:
            self._episode_open = False
        info = self._info(status, success)
        info["object_off_table"] = off_table
        return self._observe(), float(reward), terminated, truncated, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        c = self.scene.client
        view = c.computeViewMatrixFromYawPitchRoll(
            cameraTargetPosition=[0.4, 0.0, self.scene.table_top()],
            distance=1.4, yaw=60, pitch=-30, roll=0, upAxisIndex=2,
        )
        proj = c.computeProjectionMatrixFOV(fov=50, aspect=4 / 3, nearVal=0.05, farVal=5.0)
        _, _, rgba, _, _ = c.getCameraImage(320, 240, view, proj)
        return np.asarray(rgba, dtype=np.uint8).reshape(240, 320, 4)[:, :, :3]

    def close(self):
        if getattr(self, "scene", None) is not None:
            self.scene.close()
            self.scene = None

    # ── task ───────────────────────────────────────────────────────────────

    def _observe(self) -> np.ndarray:
        scene = self.scene
        c = scene.client
        tcp_pos, tcp_orn, tcp_vel = scene.tcp_state()
        tcp_pos, tcp_orn = scene.to_base(tcp_pos, tcp_orn)
        obj_pos, obj_orn = scene.object_pose()
        obj_pos, obj_orn = scene.to_base(obj_pos, obj_orn)
        inv_orn = c.invertTransform([0, 0, 0], scene.base_orn)[1]
        tcp_vel = c.multiplyTransforms([0, 0, 0], inv_orn, tcp_vel, [0, 0, 0, 1])[0]
        obs = np.concatenate(
            [
                scene.arm_positions(),
                tcp_pos,
                c.getEulerFromQuaternion(tcp_orn),
                obj_pos,
                obj_orn,
                tcp_vel,
                [scene.gripper_opening()],
            ]
        )
        return obs.astype(np.float32)

    def _status(self) -> dict:
        scene = self.scene
        contacts = scene.pad_contacts()
        opening = scene.gripper_opening()
        grasped = (
            scene.gripper_target < scene.max_opening() * 0.5
            and all(contacts)
            and opening > 0.005
        )
        obj = np.array(scene.object_pose()[0])
        tcp = np.array(scene.tcp_state()[0])
        return {
            "grasped": bool(grasped),
            "lift": float(obj[2] - scene.rest_height()),
            "ee_object_distance": float(np.linalg.norm(obj - tcp)),
        }

    def _reward(self, status: dict, success: bool, off_table: bool) -> float:
        w = self.weights
        distance = status["ee_object_distance"]
        if self.reward_type == "sparse":
            reward = w["success"] if success else 0.0
        else:
            reward = w["approach"] * (self.previous_distance - distance)
            if distance < w["near_radius"]:
                reward += w["near"]
            if status["grasped"] and not self.grasp_paid:
                reward += w["grasp"]
                self.grasp_paid = True
            if success:
                reward += w["lift_hold"]
            reward -= w["time_penalty"]
            if off_table:
                reward -= w["off_table_penalty"]
        self.previous_distance = distance
        return reward

    def _info(self, status: dict, success: bool) -> dict:
        return {
            **status,
            "success": success,
            # Stable-Baselines3's evaluation reads `is_success` at the end of an episode.
            "is_success": success,
            "success_streak": self.success_streak,
            "elapsed_steps": self.steps,
        }
