"""A Stable-Baselines3 ``VecEnv`` implemented natively: Rust threads step every env with the
GIL released, and a step moves one batch of actions in and one batch of observations out."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from fairgrasp import _native
from fairgrasp.envs import box, observation_space


class FairgraspVecEnv(VecEnv):
    """``n_envs`` copies of a fairgrasp env as an SB3 ``VecEnv``
    (``fairgrasp.make_vec_env(env_id, n_envs, **config)``).

    As SB3's own vector envs: ``dones`` is terminated or truncated, an env whose episode ends is
    reset at once and its info holds ``terminal_observation`` and ``TimeLimit.truncated``, and
    ``seed(s)`` makes the next reset seed env ``i`` with ``s + i``. Infos also carry
    ``is_success`` (read by ``EvalCallback``) and, at an episode's end, ``episode`` (``r``,
    ``l``, ``t``, as SB3's ``Monitor`` writes it). Without a seed, the first reset draws one
    from numpy's global generator (which SB3's ``set_random_seed`` seeds), so the envs never
    play the same episodes.

    :param threads: Rust threads stepping the envs (0: one per CPU, at most one per env).
    :param seed: seed of the first reset (as ``seed(seed)``).
    Other parameters as :class:`fairgrasp.FairgraspEnv`.

    ``get_attr``/``env_method`` reach what a Rust env has (``render_mode``, ``metadata``,
    ``observation_space``, ``action_space``, ``spec``, ``env_id``, ``config``; ``render``,
    ``reset``, ``config_toml``); ``set_attr`` keeps Python-side attributes that ``get_attr``
    returns.
    """

    def __init__(
        self,
        env_id: str = "FaArmGrasp-v0",
        n_envs: int = 8,
        threads: int = 0,
        seed: int | None = None,
        render_mode: str | None = None,
        rescale_action: bool = True,
        obs_mode: str | None = None,
        **config: Any,
    ) -> None:
        self._envs = _native.VecEnv(
            env_id, n_envs, config or None, threads, rescale_action, render_mode, obs_mode
        )
        self.env_id = env_id
        self.config = config
        self._render_mode = render_mode
        self._python_attrs: list[dict[str, Any]] = [{} for _ in range(n_envs)]
        self._actions: np.ndarray | None = None
        self._started = False
        super().__init__(n_envs, observation_space(self._envs), box(self._envs.action_bounds()))
        if seed is not None:
            self.seed(seed)

    @property
    def threads(self) -> int:
        """Rust threads stepping the envs."""
        return self._envs.threads

    def reset(self) -> Any:
        seeds = self._seeds
        if all(s is None for s in seeds):
            if self._started:
                obs, infos = self._envs.reset(None)
            else:
                first = int(np.random.randint(0, 2**31 - 1))
                obs, infos = self._envs.reset(first)
        elif all(s == seeds[0] + i for i, s in enumerate(seeds)):
            obs, infos = self._envs.reset(seeds[0])
        else:
            infos = [self._envs.reset_env(i, s)[1] for i, s in enumerate(seeds)]
            obs = self._envs.observations()
        self._started = True
        self.reset_infos = list(infos)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async()")
        actions = np.asarray(self._actions, dtype=np.float32).reshape(self.num_envs, -1)
        self._actions = None
        obs, rewards, terminated, truncated, infos = self._envs.step(actions)
        for i, info in enumerate(infos):
            reset_info = info.pop("reset_info", None)
            if reset_info is not None:
                self.reset_infos[i] = reset_info
        return obs, rewards, terminated | truncated, infos

    def close(self) -> None:
        self._envs.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [self._envs.render_env(i) for i in range(self.num_envs)]

    # -- attributes and methods of the envs -------------------------------------------------

    def _indices(self, indices: VecEnvIndices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices if isinstance(indices, Iterable) else [indices])

    def _native_attr(self, name: str) -> Any:
        if name == "render_mode":
            return self._render_mode
        if name == "metadata":
            return self._envs.metadata()
        if name == "observation_space":
            return self.observation_space
        if name == "action_space":
            return self.action_space
        if name == "env_id":
            return self.env_id
        if name == "config":
            return dict(self.config)
        if name == "spec":
            import gymnasium as gym

            return gym.spec(f"fairgrasp/{self.env_id}")
        raise AttributeError(
            f"{self.env_id} envs have no attribute {name!r} (they are Rust envs: "
            "render_mode, metadata, observation_space, action_space, spec, env_id and config, "
            "and what set_attr stored)"
        )

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        out = []
        for i in self._indices(indices):
            if attr_name in self._python_attrs[i]:
                out.append(self._python_attrs[i][attr_name])
            else:
                out.append(self._native_attr(attr_name))
        return out

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        for i in self._indices(indices):
            self._python_attrs[i][attr_name] = value

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        out = []
        for i in self._indices(indices):
            if method_name == "render":
                out.append(self._envs.render_env(i))
            elif method_name == "reset":
                out.append(self._envs.reset_env(i, method_kwargs.get("seed")))
            elif method_name == "config_toml":
                out.append(self._envs.config_toml())
            elif method_name == "get_wrapper_attr":
                out.append(self.get_attr(method_args[0], i)[0])
            else:
                raise AttributeError(
                    f"{self.env_id} envs have no method {method_name!r} "
                    "(render, reset, config_toml and get_wrapper_attr are available)"
                )
        return out

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        # The envs are Rust envs: no Gymnasium wrapper is ever around them.
        return [False for _ in self._indices(indices)]

    def __repr__(self) -> str:
        return f"FairgraspVecEnv({self.env_id!r}, n_envs={self.num_envs}, threads={self.threads})"
