"""A scripted pick driven through the reference env's `step()`: open, move above the cube with
the fingers across two of its faces, descend, close, lift and hold, using PyBullet's inverse
kinematics and only the env's joint-delta actions (what a policy does)."""

from __future__ import annotations

import math

import numpy as np

from .env import FaArmGraspRefEnv


def _grasp_yaw(object_yaw: float, reference: float) -> float:
    """The one of the cube's four symmetric yaws nearest the home TCP yaw (least wrist travel)."""
    best, best_gap = object_yaw, math.inf
    for k in range(-4, 5):
        candidate = object_yaw + k * math.pi / 2
        gap = (candidate - reference + math.pi) % (2 * math.pi) - math.pi
        if abs(gap) < best_gap:
            best, best_gap = reference + gap, abs(gap)
    return best


def _ik(env: FaArmGraspRefEnv, position, yaw: float) -> np.ndarray:
    """Joint angles putting the TCP at `position` (world), pointing down, fingers along `yaw`."""
    scene = env.scene
    c = scene.client
    orn = c.getQuaternionFromEuler([math.pi, 0.0, yaw])
    lower = [*scene.arm_limits[:, 0], 0.0, 0.0]
    upper = [*scene.arm_limits[:, 1], scene.finger_max, scene.finger_max]
    q = c.calculateInverseKinematics(
        scene.robot, scene.tcp, list(position), orn,
        lowerLimits=lower, upperLimits=upper,
        jointRanges=[u - l for u, l in zip(upper, lower)],
        restPoses=[*env.arm_target, 0.0, 0.0],
        maxNumIterations=200, residualThreshold=1e-5,
    )
    return np.array(q[:6])


def scripted_pick(env: FaArmGraspRefEnv, seed: int) -> tuple[bool, int]:
    """Runs one episode; returns (success, control steps taken)."""
    u = env.unwrapped
    env.reset(seed=seed)
    scene = u.scene
    c = scene.client
    pos, orn = scene.object_pose()
    yaw = _grasp_yaw(c.getEulerFromQuaternion(orn)[2], scene.home_tcp_yaw)
    d = u.max_joint_delta
    above = np.array(pos) + [0, 0, 0.15]
    grasp = np.array(pos)

    # Waypoints: (TCP position, gripper open, control steps at most, leave once reached).
    plan = [(above, True, 40, True)]
    plan += [(above + (grasp - above) * k / 12, True, 2, False) for k in range(1, 13)]
    plan += [(grasp, True, 4, False), (grasp, False, 10, False)]
    plan += [(grasp + [0, 0, 0.01 * k], False, 1, False) for k in range(1, 13)]
    plan += [(grasp + [0, 0, 0.12], False, 100, False)]  # hold until the env ends the episode

    steps = 0
    for target, open_, budget, early_exit in plan:
        q_goal = _ik(u, target, yaw)
        for _ in range(budget):
            delta = np.clip(q_goal - u.arm_target, -d, d)
            action = np.array([*delta, 1.0 if open_ else -1.0], dtype=np.float32)
            _, _, terminated, truncated, info = env.step(action)
            steps += 1
            if terminated or truncated:
                return bool(info["success"]), steps
            if early_exit and np.max(np.abs(q_goal - u.arm_target)) < 1e-3:
                break
    return False, steps
