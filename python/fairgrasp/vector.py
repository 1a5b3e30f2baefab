"""Gymnasium's ``VectorEnv`` face of the native vector env (Rust threads step every env)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from fairgrasp import _native
from fairgrasp.envs import box, observation_space


class FairgraspVectorEnv(gym.vector.VectorEnv):
    """``num_envs`` copies of a fairgrasp env as a :class:`gymnasium.vector.VectorEnv`.

    Envs whose episode ends are reset in the same step (``autoreset_mode`` ``SAME_STEP``): the
    returned observation row starts the next episode, ``infos["final_obs"]`` and
    ``infos["final_info"]`` hold the finished one's (masked by ``infos["_final_obs"]``).
    ``reset(seed=s)`` resets env ``i`` with ``s + i``.

    :param threads: Rust threads stepping the envs (0: one per CPU, at most one per env).
    Other parameters as :class:`fairgrasp.FairgraspEnv`.
    """

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(
        self,
        env_id: str = "FaArmGrasp-v0",
        num_envs: int = 8,
        threads: int = 0,
        render_mode: str | None = None,
        rescale_action: bool = True,
        obs_mode: str | None = None,
        **config: Any,
    ) -> None:
        self._envs = _native.VecEnv(
            env_id, num_envs, config or None, threads, rescale_action, render_mode, obs_mode
        )
        self.env_id = env_id
        self.num_envs = num_envs
        self.single_observation_space = observation_space(self._envs)
        self.single_action_space = box(self._envs.action_bounds())
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.metadata = {**self._envs.metadata(), "autoreset_mode": AutoresetMode.SAME_STEP}
        self.render_mode = render_mode
        self._seeded = False

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        if isinstance(seed, list):
            if len(seed) != self.num_envs:
                raise ValueError(f"{len(seed)} seeds for {self.num_envs} envs")
            infos: dict[str, Any] = {}
            for i, s in enumerate(seed):
                _obs, info = self._envs.reset_env(i, s)
                infos = self._add_info(infos, info, i)
            self._seeded = True
            return self._envs.observations(), infos
        if seed is None and not self._seeded:
            seed = int(np.random.SeedSequence().generate_state(1, dtype=np.uint64)[0] >> 1)
        self._seeded = True
        obs, reset_infos = self._envs.reset(seed)
        infos = {}
        for i, info in enumerate(reset_infos):
            infos = self._add_info(infos, info, i)
        return obs, infos

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        obs, rewards, terminated, truncated, step_infos = self._envs.step(actions)
        infos: dict[str, Any] = {}
        for i, info in enumerate(step_infos):
            final_obs = info.pop("terminal_observation", None)
            if final_obs is not None:
                reset_info = info.pop("reset_info")
                info.pop("episode", None)
                info.pop("TimeLimit.truncated", None)
                infos = self._add_info(infos, {"final_obs": final_obs, "final_info": info}, i)
                info = reset_info
            infos = self._add_info(infos, info, i)
        return obs, rewards.astype(np.float64), terminated, truncated, infos

    def render(self) -> tuple[Any, ...] | None:
        if self.render_mode is None:
            return None
        return tuple(self._envs.render_env(i) for i in range(self.num_envs))

    def close_extras(self, **kwargs: Any) -> None:
        self._envs.close()
