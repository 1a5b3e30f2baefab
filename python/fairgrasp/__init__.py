"""fairgrasp: FR5 grasping by reinforcement learning, from Python.

The engine is Rust (``fairgrasp._native``); this package gives it the faces Python users already
know:

- every registered env as a :class:`gymnasium.Env`, registered under ``fairgrasp/<id>``::

      import gymnasium, fairgrasp
      env = gymnasium.make("fairgrasp/FaArmGrasp-v0", control={"action_mode": "cartesian"})

- :func:`make_vec_env`: a Stable-Baselines3 ``VecEnv`` stepped by Rust threads, GIL released::

      from stable_baselines3 import PPO
      PPO("MlpPolicy", fairgrasp.make_vec_env("FaArmGrasp-v0", 8)).learn(100_000)

- :class:`Policy`: a model trained by ``fairgrasp train``; ``predict`` as in SB3;
- :func:`train` and :func:`evaluate`: the native trainer and evaluator;
- :class:`PolicyDriver`: a saved model driven exactly as ``fairgrasp deploy`` drives it (state
  estimator, observation, action mapping, set-point ramp, success rule), fed by readings from
  any simulator (``bench/sim2sim`` runs it on the cell in MuJoCo);
- :class:`GripperRamp`: the gripper controller's set point after a ``MoveGripper``, the twin's
  and training's model, for a simulator standing in for the arm.

Settings are the env's TOML keys (``fairgrasp env config --env ID`` lists them): nested dicts
for sections or dotted keys (``**{"control.action_mode": "cartesian"}``). Actions are in [-1, 1]
by default (``rescale_action=True``), as the native trainer learns them; pass
``rescale_action=False`` for the env's own units (joint-angle deltas in radians, ...).
"""

import os

# The networks' matrix products on one thread, as the `fairgrasp` command runs them
# (crates/cli/src/main.rs: a SAC gradient step ~2.5x faster than on two), unless the user set
# it. Left unset, candle also re-reads /proc/cpuinfo for its default on every product.
os.environ.setdefault("RAYON_NUM_THREADS", "1")

from fairgrasp._native import (  # noqa: E402 (after the thread setting above)
    ActionError,
    ConfigError,
    GripperRamp,
    ModelError,
    PolicyDriver,
    __version__,
    list_envs,
)
from fairgrasp.envs import FairgraspEnv, env_config, make, register_envs
from fairgrasp.policy import Policy
from fairgrasp.training import default_train_config, evaluate, train
from fairgrasp.vector import FairgraspVectorEnv

register_envs()


def make_vec_env(env_id: str = "FaArmGrasp-v0", n_envs: int = 8, **kwargs):
    """An SB3 ``VecEnv`` of ``n_envs`` copies of ``env_id`` (see :class:`fairgrasp.sb3.FairgraspVecEnv`).

    Imported lazily: Stable-Baselines3 is only needed by those who use it.
    """
    from fairgrasp.sb3 import FairgraspVecEnv

    return FairgraspVecEnv(env_id, n_envs, **kwargs)


__all__ = [
    "ActionError",
    "ConfigError",
    "FairgraspEnv",
    "FairgraspVectorEnv",
    "GripperRamp",
    "ModelError",
    "Policy",
    "PolicyDriver",
    "__version__",
    "default_train_config",
    "env_config",
    "evaluate",
    "list_envs",
    "make",
    "make_vec_env",
    "register_envs",
    "train",
]
