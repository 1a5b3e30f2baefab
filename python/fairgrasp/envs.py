"""Every registered fairgrasp env as a :class:`gymnasium.Env`, and their registration."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from fairgrasp import _native

NAMESPACE = "fairgrasp"
# Every mode an env of ours may offer; each instance's metadata lists its own.
ALL_RENDER_MODES = ["ansi", "rgb_array", "depth_array", "segmentation_array"]


def box(bounds: tuple[np.ndarray, np.ndarray]) -> spaces.Box:
    low, high = bounds
    return spaces.Box(low=low, high=high, dtype=np.float32)


def observation_space(native: Any) -> spaces.Space:
    """One env's observation space: the state box, or with camera images a ``Dict`` of it
    (``state``) and a ``(H, W, C)`` uint8 box per camera (``scene_rgb``, ``wrist_depth``, …),
    as SB3's ``MultiInputPolicy`` reads it."""
    state = box(native.observation_bounds())
    views = native.image_views()
    if not views:
        return state
    images = {
        name: spaces.Box(low=0, high=255, shape=(h, w, c), dtype=np.uint8)
        for name, h, w, c in views
    }
    return spaces.Dict({"state": state, **images})


class FairgraspEnv(gym.Env):
    """A fairgrasp env (Rust) behind Gymnasium's ``Env`` API.

    :param env_id: a registered id (``fairgrasp.list_envs()``), e.g. ``"FaArmGrasp-v0"``.
    :param render_mode: ``"rgb_array"``, ``"depth_array"``, ``"segmentation_array"`` or
        ``"ansi"`` (arm tasks), from the ``[render]`` camera.
    :param rescale_action: actions in [-1, 1], mapped onto the env's own bounds (default, as
        the native trainer learns); ``False`` for the env's own units.
    :param obs_mode: ``"state"`` (default: the task's observation vector), ``"rgb+state"``,
        ``"depth+state"`` or ``"rgbd+state"`` (arm tasks; ManiSkill's names): a dict of the
        arm's own readings (``state``, never the object's pose) and uint8 camera images
        (``[camera]`` settings: size, scene and wrist cameras).
    :param config: the env's settings by their TOML keys: sections as dicts
        (``control={"action_mode": "cartesian"}``) or dotted keys.

    Observations are float32 vectors inside the observation space's (finite) bounds, or dicts
    of one and ``H×W×C`` uint8 images in a pixel ``obs_mode``. A
    wrong-shaped, NaN or infinite action raises :class:`fairgrasp.ActionError`; an unknown or
    out-of-range setting raises :class:`fairgrasp.ConfigError`. Without a seed, the first
    ``reset`` draws one from ``np_random`` (fresh entropy, as Gymnasium's envs do).
    """

    metadata: dict[str, Any] = {"render_modes": ALL_RENDER_MODES, "render_fps": 30}

    def __init__(
        self,
        env_id: str = "FaArmGrasp-v0",
        render_mode: str | None = None,
        rescale_action: bool = True,
        obs_mode: str | None = None,
        **config: Any,
    ) -> None:
        self._env = _native.Env(env_id, config or None, rescale_action, render_mode, obs_mode)
        self.env_id = env_id
        self.config = config
        self.observation_space = observation_space(self._env)
        self.action_space = box(self._env.action_bounds())
        self.metadata = self._env.metadata()
        self.render_mode = render_mode
        self._seeded = False

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        if seed is None and not self._seeded:
            seed = int(self.np_random.integers(0, 2**63 - 1))
        self._seeded = True
        return self._env.reset(seed)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        return self._env.step(action)

    def render(self) -> np.ndarray | str | None:
        return self._env.render()

    def close(self) -> None:
        self._env.close()

    def config_toml(self) -> str:
        """Every setting of this env, defaults filled in, as TOML text."""
        return self._env.config_toml()

    def __repr__(self) -> str:
        return f"FairgraspEnv({self.env_id!r})"


def make(env_id: str = "FaArmGrasp-v0", **kwargs: Any) -> FairgraspEnv:
    """A bare :class:`FairgraspEnv` (no Gymnasium wrappers): ``fairgrasp.make("FaArmGrasp-v0")``."""
    return FairgraspEnv(env_id, **kwargs)


def env_config(env_id: str = "FaArmGrasp-v0", **config: Any) -> str:
    """Every setting of ``env_id`` (with ``config`` applied and checked) as TOML text."""
    return _native.env_config(env_id, config or None)


def register_envs() -> None:
    """Registers every fairgrasp env with Gymnasium as ``fairgrasp/<id>`` (done on import)."""
    for env_id, _summary in _native.list_envs():
        full_id = f"{NAMESPACE}/{env_id}"
        if full_id in gym.registry:
            continue
        gym.register(
            id=full_id,
            entry_point="fairgrasp.envs:FairgraspEnv",
            kwargs={"env_id": env_id},
            # The envs end their own episodes (time limits are settings, `task.max_episode_steps`).
            max_episode_steps=None,
        )
