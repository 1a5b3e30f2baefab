"""`fairgrasp.PolicyDriver` (the deployment loop's policy side, fed by any simulator's readings)
and `bench/sim2sim` (a model on the grasp cell simulated in MuJoCo)."""

from __future__ import annotations

import importlib.util
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import REPO

import fairgrasp

ZERO6 = [0.0] * 6
IDENTITY = [0.0, 0.0, 0.0, 1.0]


def readings(driver: fairgrasp.PolicyDriver, cube=(0.5, 0.0, 0.025), percent=100):
    """Readings of an arm resting at the model's home with the gripper open."""
    return [math.degrees(q) for q in driver.home_rad], ZERO6, percent, list(cube), IDENTITY


def test_the_driver_runs_a_saved_model_as_the_deployment_does(trained_model):
    driver = fairgrasp.PolicyDriver(trained_model)
    assert driver.env_id == "FaArmGrasp-v0"
    assert driver.servo_ticks == 4 and math.isclose(driver.control_period, 1 / 30, rel_tol=1e-6)
    assert math.isclose(driver.servo_period * driver.servo_ticks, driver.control_period, rel_tol=1e-9)
    assert driver.max_steps == 100 and driver.success_hold_steps == 10
    assert len(driver.home_rad) == 6
    limits = np.array(driver.joint_limits_rad)
    speed_cap, acc_cap = driver.ramp_caps
    assert math.isclose(speed_cap, math.radians(180)) and math.isclose(acc_cap, math.radians(720))

    assert driver.last_step() is None
    set_points, gripper_open, held = driver.begin(*readings(driver))
    assert not held and isinstance(gripper_open, bool)
    # What the policy saw and chose, as `fairgrasp eval --trace` writes it: the action's
    # gripper value decides the command.
    obs, action = driver.last_step()
    assert len(obs) == 38 and len(action) == 5
    assert (action[-1] > 0) == gripper_open
    previous = np.array(driver.home_rad)
    velocity = np.zeros(6)
    for step in range(8):
        if step > 0:
            # Synthetic readings: the arm exactly where the last set point put it.
            joints = [math.degrees(q) for q in previous]
            speeds = [math.degrees(v) for v in velocity]
            set_points, gripper_open, held = driver.step(joints, speeds, 100, [0.5, 0.0, 0.025], IDENTITY)
            assert not held
        points = np.array(set_points)
        assert points.shape == (driver.servo_ticks, 6)
        assert np.all(points >= limits[:, 0] - 1e-9) and np.all(points <= limits[:, 1] + 1e-9)
        # The ramp's caps hold from set point to set point.
        for p in points:
            v = (p - previous) / driver.servo_period
            assert np.all(np.abs(v) <= speed_cap * (1 + 1e-6))
            assert np.all(np.abs(v - velocity) <= acc_cap * driver.servo_period * (1 + 1e-6))
            previous, velocity = p, v
    assert driver.steps == 8
    # Holding (after the success rule held, the deployment streams towards the last target).
    assert np.array(driver.hold()).shape == (driver.servo_ticks, 6) and driver.steps == 8
    assert driver.hold_after_success == 5
    estimate = driver.estimate()
    assert estimate is not None and estimate["pad_contacts"] == [False, False]

    placement = driver.placement(2_000_000_000)
    assert len(placement["position"]) == 3 and len(placement["orientation_xyzw"]) == 4
    assert math.isclose(np.linalg.norm(placement["orientation_xyzw"]), 1.0, rel_tol=1e-6)
    assert placement["half_extents"] == pytest.approx([0.025] * 3)
    assert placement["position"][2] == pytest.approx(placement["rest_z"], abs=2e-3)
    # The same seed, the same layout (what `fairgrasp eval` resets to).
    assert driver.placement(2_000_000_000) == placement
    assert driver.placement(2_000_000_001)["position"] != placement["position"]


def test_bad_readings_and_models_raise_clear_errors(tmp_path, trained_model):
    driver = fairgrasp.PolicyDriver(trained_model)
    with pytest.raises(RuntimeError, match="begin"):
        driver.step(*readings(driver))
    joints, speeds, percent, cube, quat = readings(driver)
    with pytest.raises(ValueError, match="joints_deg.*6"):
        driver.begin(joints[:5], speeds, percent, cube, quat)
    with pytest.raises(ValueError, match="joint_speeds_deg.*NaN"):
        driver.begin(joints, [float("nan")] + ZERO6[1:], percent, cube, quat)
    with pytest.raises(ValueError, match="gripper_percent"):
        driver.begin(joints, speeds, 101, cube, quat)
    with pytest.raises(ValueError, match="gripper_percent"):
        driver.begin(joints, speeds, 50.5, cube, quat)
    with pytest.raises(ValueError, match="object_quat_xyzw.*unit"):
        driver.begin(joints, speeds, percent, cube, [0.0, 0.0, 0.0, 2.0])
    with pytest.raises(ValueError, match="object_pos"):
        driver.begin(joints, speeds, percent, "here", quat)
    with pytest.raises(fairgrasp.ModelError, match="missing"):
        fairgrasp.PolicyDriver(tmp_path / "missing")
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "model.json").write_text((trained_model / "model.json").read_text())
    (broken / "model.safetensors").write_bytes(b"\x00" * 16)
    with pytest.raises(fairgrasp.ModelError, match="model.safetensors"):
        fairgrasp.PolicyDriver(broken)


def test_the_gripper_ramp_moves_as_the_twin_s_gripper_does():
    """`fairgrasp.GripperRamp` is the Rust model the twin and `[control.gripper]` use: a move
    leaves from the fingers at its speed and stops at its target; bad numbers are refused."""
    ramp = fairgrasp.GripperRamp(100.0)
    assert ramp.full_speed_percent_per_s == 1500.0
    ramp.command(100.0, 0.0, 375.0)
    assert ramp.target == 0.0
    assert ramp.advance(0.1) == pytest.approx(62.5)
    assert ramp.advance(1.0) == 0.0
    ramp.command(40.0, 100.0, 1500.0)
    assert ramp.advance(0.02) == pytest.approx(70.0)
    with pytest.raises(ValueError, match="dt"):
        ramp.advance(float("nan"))
    with pytest.raises(ValueError, match="fingers_percent"):
        ramp.command(float("inf"), 0.0, 100.0)


@pytest.mark.skipif(importlib.util.find_spec("mujoco") is None, reason="mujoco is not installed")
def test_bench_sim2sim_runs_episodes_in_mujoco(tmp_path, trained_model):
    out = tmp_path / "sim2sim.json"
    env = dict(os.environ, FAIRGRASP_VENV=os.path.dirname(os.path.dirname(sys.executable)))
    done = subprocess.run(
        [str(REPO / "bench" / "sim2sim"), "--no-build", "--model", str(trained_model),
         "--episodes", "2", "--json", "--out", str(out), "-v", "--trace", str(tmp_path / "trace.jsonl")],
        capture_output=True, text=True, timeout=300, env=env,
    )
    assert done.returncode == 0, done.stderr + done.stdout
    assert "MuJoCo" in done.stdout and "fairgrasp" in done.stdout
    summary = json.loads(done.stdout.strip().splitlines()[-1])
    assert summary["episodes"] == 2 and 0 <= summary["mujoco"]["successes"] <= 2
    detail = json.loads(out.read_text())["episodes_detail"]
    assert [e["seed"] for e in detail] == [2_000_000_000, 2_000_000_001]
    assert all(1 <= e["steps"] <= 100 for e in detail)
    # One trace line per step the policy acted, in `fairgrasp eval --trace`'s format.
    lines = [json.loads(line) for line in (tmp_path / "trace.jsonl").read_text().splitlines()]
    assert len(lines) >= sum(e["steps"] for e in detail) - 2
    assert all(len(line["obs"]) == 38 and len(line["action"]) == 5 for line in lines)
    # With MuJoCo's own state at the readings: the observation's TCP (12:15) and object
    # position (21:24) are the cell's, read through the deployment's estimator.
    first = lines[0]
    assert first["seed"] == 2_000_000_000 and [l["seed"] for l in lines][-1] == 2_000_000_001
    assert first["obs"][12:15] == pytest.approx(first["world"]["tcp"], abs=2e-3)
    assert first["obs"][21:24] == pytest.approx(first["world"]["cube"], abs=1e-4)
    assert 0.08 < first["world"]["opening"] < 0.1 and first["world"]["pads_touch"] == [False, False]
