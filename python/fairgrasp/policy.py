"""Models trained by ``fairgrasp train``, acting from Python."""

from __future__ import annotations

import json
import os
from typing import Any

import numpy as np

from fairgrasp import _native


class Policy:
    """A saved model (``runs/NAME/best``, or a run directory for its best model).

    It acts through the same Rust code as ``fairgrasp eval`` and the deployment loop, with the
    model's observation normalisation applied, so ``predict`` gives the actions they give.
    Actions are in the model's action space: [-1, 1] for the trainer's models, which is what
    ``gymnasium.make("fairgrasp/...")`` and ``fairgrasp.make_vec_env`` take by default.
    """

    def __init__(self, native: _native.Policy) -> None:
        self._policy = native
        self.meta: dict[str, Any] = json.loads(native.meta_json())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Policy:
        """Loads a model directory; raises :class:`fairgrasp.ModelError` naming what is wrong."""
        return cls(_native.Policy.load(os.fspath(path)))

    def predict(
        self,
        observation: np.ndarray | dict[str, np.ndarray],
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, None]:
        """SB3's ``predict``: ``(actions, None)`` for one observation ``(obs_dim,)`` or a batch
        ``(n, obs_dim)``, or for a camera policy one ``Dict`` observation (``obs_mode=
        "rgb+state"``: ``{"state": (obs_dim,), "scene_rgb": (h, w, 3), ...}``) or a batch of
        them (each entry with a leading ``n``). Deterministic: the distribution's mode;
        otherwise a sample from the policy's own seeded stream (:meth:`set_seed`; a camera
        policy always acts deterministically). The state arguments exist for SB3's signature;
        the policies are not recurrent."""
        if isinstance(observation, dict):
            return self._act_on_dict(observation, deterministic), None
        if self.image_views:
            raise ValueError(
                "this camera policy reads a Dict observation: "
                f"{{'state', {', '.join(repr(v[0]) for v in self.image_views)}}}"
            )
        return self._policy.act(observation, deterministic), None

    def _act_on_dict(self, observation: dict[str, np.ndarray], deterministic: bool) -> np.ndarray:
        if "state" not in observation:
            raise ValueError(f"invalid observation: no 'state' among {sorted(observation)}")
        state = np.asarray(observation["state"], dtype=np.float32)
        rows = state.shape[0] if state.ndim == 2 else None
        parts = []
        for name, height, width, channels in self.image_views:
            if name not in observation:
                raise ValueError(f"invalid observation: no {name!r} among {sorted(observation)}")
            image = np.asarray(observation[name])
            want = (height, width, channels) if rows is None else (rows, height, width, channels)
            if image.shape != want or image.dtype != np.uint8:
                raise ValueError(
                    f"invalid observation: {name!r} must be uint8 of shape {want}, "
                    f"got {image.dtype} {image.shape}"
                )
            parts.append(image.reshape(1 if rows is None else rows, -1))
        images = np.ascontiguousarray(np.concatenate(parts, axis=1) if parts else np.zeros((0,), np.uint8))
        if rows is None:
            images = images.reshape(-1)
        return self._policy.act_with_images(state, images, deterministic)

    @property
    def image_views(self) -> list[tuple[str, int, int, int]]:
        """The camera images a camera policy reads, ``(name, height, width, channels)``;
        empty for a policy of the observation vector."""
        return self._policy.image_views()

    def set_seed(self, seed: int) -> None:
        """Restarts the stream of stochastic actions."""
        self._policy.set_seed(seed)

    @property
    def obs_dim(self) -> int:
        return self._policy.obs_dim

    @property
    def act_dim(self) -> int:
        return self._policy.act_dim

    @property
    def algo(self) -> str:
        return self.meta["algo"]

    @property
    def env_id(self) -> str:
        """The registered env the model was trained on."""
        return self.meta["env_id"]

    @property
    def env_config(self) -> dict[str, Any]:
        """The settings of that env (TOML sections as dicts), for ``fairgrasp.make`` or
        ``gymnasium.make("fairgrasp/" + policy.env_id, **policy.env_config)``."""
        return json.loads(self._policy.env_settings_json())

    @property
    def path(self) -> str | None:
        p = self._policy.path
        return None if p is None else os.fspath(p)

    def make_env(self, **kwargs: Any):
        """A :class:`fairgrasp.FairgraspEnv` like the one the model was trained on (``kwargs``
        such as ``render_mode`` are added)."""
        from fairgrasp.envs import FairgraspEnv

        return FairgraspEnv(self.env_id, **{**self.env_config, **kwargs})

    def __repr__(self) -> str:
        return repr(self._policy)
