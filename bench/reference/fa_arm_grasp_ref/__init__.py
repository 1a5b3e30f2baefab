"""PyBullet reference of fairgrasp's grasp task, for side-by-side benchmarks (bench/run)."""

import gymnasium as gym

from .env import FaArmGraspRefEnv
from .scripted import scripted_pick

ENV_ID = "FaArmGraspRef-v0"

if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point="fa_arm_grasp_ref.env:FaArmGraspRefEnv")

__all__ = ["ENV_ID", "FaArmGraspRefEnv", "scripted_pick"]
