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
        observation: np.ndarray,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, None]:
        """SB3's ``predict``: ``(actions, None)`` for one observation ``(obs_dim,)`` or a batch
        ``(n, obs_dim)``. Deterministic: the distribution's mode; otherwise a sample from the
        policy's own seeded stream (:meth:`set_seed`). The state arguments exist for SB3's
        signature; the policies are not recurrent."""
        return self._policy.act(observation, deterministic), None

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
