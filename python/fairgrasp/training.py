"""The native trainer and evaluator (what ``fairgrasp train`` and ``fairgrasp eval`` run), driven
from Python with the GIL released."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from typing import Any

from fairgrasp import _native

Progress = dict[str, Any]


def train(
    config: dict[str, Any] | str | os.PathLike[str] | None = None,
    *,
    run_dir: str | os.PathLike[str] | None = None,
    env_id: str | None = None,
    algo: str | None = None,
    callback: Callable[[Progress], bool | None] | None = None,
    resume: bool = False,
    **settings: Any,
) -> dict[str, Any]:
    """Trains a policy with the native PPO or SAC and returns the run's summary.

    :param config: the training configuration: a dict of its TOML keys, or a TOML file
        (``configs/ppo_grasp.toml`` documents every key). Default: the built-in tuned settings of
        ``algo`` on ``env_id`` (``fairgrasp.default_train_config``).
    :param run_dir: where logs, checkpoints and models go (default ``runs/<algo>_<env>``, the
        next free one). The best model lands in ``<run_dir>/best``.
    :param callback: called after every iteration with a progress dict (``num_timesteps``,
        ``fps``, ``ep_rew_mean``, ``rollout_success_rate``, ``eval_count``, ``last_eval``, …);
        returning ``False`` stops the run, which then writes its final model as usual.
    :param resume: continue the run in ``run_dir`` from its latest checkpoint.
    :param settings: keys to change, dotted or nested: ``total_timesteps=20_000``,
        ``**{"ppo.learning_rate": 1e-4}``, ``eval={"freq": 10_000}``.

    Ctrl-C stops the run between iterations (the final model is saved) and raises
    ``KeyboardInterrupt``; an exception in the callback stops it the same way and propagates.
    """
    summary = _native.train(
        config=os.fspath(config) if isinstance(config, os.PathLike) else config,
        run_dir=None if run_dir is None else os.fspath(run_dir),
        env_id=env_id,
        algo=algo,
        settings=settings or None,
        callback=callback,
        resume=resume,
    )
    return json.loads(summary)


def evaluate(
    model: Any,
    episodes: int = 100,
    seed: int = 2_000_000_000,
    **settings: Any,
) -> dict[str, Any]:
    """A model's deterministic success rate, mean return and mean length over ``episodes``
    held-out episodes (seeds ``seed, seed + 1, …``; the default range is never used in
    training), as ``fairgrasp eval`` measures it.

    :param model: a model or run directory, or a :class:`fairgrasp.Policy` loaded from one.
    :param settings: env settings to change, e.g. ``randomization={"enabled": True}``.
    """
    path = getattr(model, "path", model)
    if path is None:
        raise ValueError("this Policy was not loaded from a directory; pass the model's path")
    return json.loads(_native.evaluate(os.fspath(path), episodes, seed, settings or None))


def default_train_config(env_id: str = "FaArmGrasp-v0", algo: str = "ppo") -> str:
    """The built-in training configuration of ``algo`` on ``env_id``, every key filled in, as
    TOML text: what :func:`train` starts from without a ``config``."""
    return _native.default_train_config(env_id, algo)
