"""Sim-to-sim: a saved fairgrasp model on the grasp cell simulated in MuJoCo (`bench/sim2sim`).

The policy runs through fairgrasp's own deployment code, through the Python face
(`fairgrasp.PolicyDriver`, python/src/driver.rs): the env's state estimator fed with controller
readings, the observation, the deterministic action, the action mapping (Cartesian deltas through
IK, lead cap, workspace box) and the set-point ramp of training's `[control.servo]`. Nothing of
that is reimplemented here: this module only plays the controller and the world.

The cell (`mujoco_scene.mjcf`, built from the same URDFs and the model's own env settings, so
masses, inertias, joint damping, armature, gains, effort limits, joint limits, table, cube and
pad friction are fairgrasp's figures):

- **Joints**: MuJoCo position actuators (kp, kd, effort limits of `[scene.arm]` and the URDF),
  driven at the controller's servo period: each control step's `servo_ticks` set points are held
  for one servo period each (8 physics steps of 1/240 s per 1/30 s step, 2 per set point), as
  fairgrasp's `[control.servo]` spreads them. The fingers: one position drive (kp 2000, kd 40,
  40 N) on the left finger, the right one coupled by a joint equality (the URDF's mimic); open
  = the full stroke, closed = 0.
- **Readings** the driver gets each control step, as a controller reports them: joints and
  speeds in degrees, the gripper in whole percent of its stroke (round(opening / max × 100),
  the opening being the pads' distance q_left + q_right: MuJoCo's mimic coupling is a soft
  joint equality that yields ~3 mm under the 40 N squeeze, where fairgrasp's 2 × q_left is
  exact; `--opening left` reads it fairgrasp's way),
  and the cube's pose in the base frame as a perception feed gives it (the current pose; the
  deployment's 30 Hz feed can be up to one period old).
- **The gripper** moves as a FAIRINO MoveGripper moves it on the twin: when the policy's
  command changes, a set point from where the fingers are at full speed (1500 % of the stroke
  per second), advanced every physics step (`fairgrasp.GripperRamp`, the twin's own model).
- **Episodes** start as fairgrasp's do: the arm at the model's home pose with the gripper open,
  the cube dropped from 1 mm above its resting height at the pose `fairgrasp eval` draws for the
  same seed (`PolicyDriver.placement`), then settled by the same rule as fairgrasp's scene
  (until the cube is still, at most one second).
- **Success** is judged in MuJoCo by the task's rule (docs/tasks.md): gripper commanded closed,
  both finger pads touching the cube (within 1 mm, fairgrasp's touch distance), opening above
  5 mm, the cube lifted more than 5 cm above its resting height and less than 8 cm from the TCP,
  for 10 consecutive control steps. The episode ends there, as a training episode does, or when
  the cube leaves the table, or at the model's step limit. When the driver's own success rule
  (on its estimated state) ends the episode first, the deployment loop's ending follows: the arm
  streamed towards its last target with the gripper as commanded for `hold_after_success` (5)
  control steps (`PolicyDriver.hold`), during which MuJoCo's streak may complete, as the twin's
  judge counts on its own clock; if it does not, the episode failed.

**Contact settings, chosen once from physics, never tuned to a policy.** MuJoCo's contacts are
soft; with its defaults (solref time constant 20 ms) a squeezed 100 g cube sinks into the pads
and slides out. `mujoco_scene` makes them stiff and critically damped instead: solref time
constant 2·dt (the fastest the 240 Hz integrator resolves stably), damping ratio 1, solimp
0.99 (99 % of the constraint's stiffness from the first 1 mm of penetration): as stiff as
MuJoCo allows at this time step, though still far softer than fairgrasp's rapier contacts at
their 300 Hz contact frequency (see below). The
friction coefficient of a pair is the one fairgrasp's engine uses for it: rapier combines the
two surfaces' configured coefficients by their mean, MuJoCo by their maximum, so the pairs whose
surfaces differ (pads against the cube and the table, the cube against the table) are declared
explicitly with the mean (pads on the cube: (1.5 + 0.8) / 2 = 1.15, not 1.5). Pyramidal friction
cones, condim 3 (sliding friction only, as rapier), Newton solver, implicit-fast integration:
MuJoCo's defaults and mujoco_scene's, left as they are.

Measured consequence (/work/notes/sim2sim.md): at 240 Hz the stiffest stable MuJoCo contact
(time constant 2·dt = 8.3 ms) is far softer than rapier's 300 Hz contacts: pads closing on the
100 g cube sink up to 1–1.5 cm into it for a control step, the gripper then reads below the
cube's width, and the deployment's estimator (rightly, for a rigid cube) infers that nothing is
held. `--timestep-divisor N` steps MuJoCo at dt / N with the time constants following (2 × its
step): a diagnostic of that sensitivity, not the cell's setting.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import time
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass
from pathlib import Path

import mujoco
import numpy as np

from .mujoco_scene import addresses, fmt, mjcf
from .scene import SceneSettings

HELD_OUT_SEED = 2_000_000_000
# fairgrasp's scene: two surfaces closer than this touch (crates/sim/src/scene/objects.rs).
TOUCH_DISTANCE = 0.001
# fairgrasp drops a placed object from this far above its resting height, then settles it.
DROP_GAP = 0.001
# The grasp rule's smallest opening (m): fingers stopped by the object, not closed on nothing.
MIN_OPENING = 0.005
PADS = ("left_finger", "right_finger")
# How the gripper's opening is read: "both" (q_left + q_right, the pads' distance) or "left"
# (2 × q_left, fairgrasp's formula); set by --opening.
OPENING = "both"


def _mean_friction_pairs(root: ET.Element, solref: str, solimp: str) -> None:
    """Declares the pairs of surfaces with different friction explicitly, with the mean of the
    two coefficients (rapier's rule) instead of MuJoCo's maximum."""
    bodies = {b.get("name"): b for b in root.iter("body")}
    world = root.find("worldbody")

    def geoms(body_name: str) -> list[ET.Element]:
        if body_name == "world":
            return world.findall("geom")
        return bodies[body_name].findall("geom")

    def friction(geom: ET.Element) -> float:
        return float(geom.get("friction").split()[0])

    for body in PADS:
        for i, g in enumerate(geoms(body)):
            g.set("name", f"{body}_{i}")
    contact = ET.SubElement(root, "contact")
    pairs = [(pad, "cube") for pad in PADS] + [(pad, "world") for pad in PADS] + [("world", "cube")]
    for a, b in pairs:
        ET.SubElement(contact, "exclude", body1=a, body2=b)
        for ga in geoms(a):
            for gb in geoms(b):
                mu = (friction(ga) + friction(gb)) / 2
                ET.SubElement(
                    contact, "pair", geom1=ga.get("name"), geom2=gb.get("name"), condim="3",
                    friction=fmt([mu, mu, 0.005, 0.0001, 0.0001]), solref=solref, solimp=solimp,
                )


def cell_mjcf(config: dict, cube: dict, root: Path | None = None, divisor: int = 1) -> str:
    """The cell's MJCF: `mujoco_scene.mjcf` for the model's settings, with episode `cube`'s
    size, mass and friction (`PolicyDriver.placement`) and the pair frictions above. `divisor`
    > 1 (a diagnostic, `--timestep-divisor`): MuJoCo steps at dt / divisor, and the contact
    and equality time constants follow (2 × its step), so contacts are that much stiffer."""
    settings = SceneSettings.from_config(config)
    tree = ET.fromstring(mjcf(settings, config, root))
    if divisor > 1:
        dt = settings.dt / divisor
        tree.find("option").set("timestep", f"{dt:.9g}")
        solref = f"{2 * dt:.6g} 1"
        tree.find("default/geom").set("solref", solref)
        for e in tree.iter("joint"):
            if e.get("joint1") is not None:
                e.set("solref", solref)
    body = next(b for b in tree.iter("body") if b.get("name") == "cube")
    geom = body.find("geom")
    geom.set("name", "cube")
    half = [float(v) for v in cube["half_extents"]]
    geom.set("size", fmt(half))
    geom.set("friction", f"{cube['friction']} 0.005 0.0001")
    mass = float(cube["mass"])
    x, y, z = (2 * h for h in half)
    inertial = body.find("inertial")
    inertial.set("mass", repr(mass))
    inertial.set("diaginertia", fmt([mass * (y * y + z * z) / 12, mass * (x * x + z * z) / 12, mass * (x * x + y * y) / 12]))
    default = tree.find("default/geom")
    _mean_friction_pairs(tree, default.get("solref"), default.get("solimp"))
    return ET.tostring(tree, encoding="unicode")


def quat_xyzw(wxyz: np.ndarray) -> list[float]:
    return [float(wxyz[1]), float(wxyz[2]), float(wxyz[3]), float(wxyz[0])]


class MujocoCell:
    """The grasp cell in MuJoCo, read and driven as a controller and a pose feed would be."""

    def __init__(self, config: dict, cube: dict, root: Path | None = None, divisor: int = 1) -> None:
        self.config = config
        self.settings = SceneSettings.from_config(config)
        self.cube_key = self._key(cube)
        self.model = mujoco.MjModel.from_xml_string(cell_mjcf(config, cube, root, divisor))
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.arm_qpos, self.arm_dof, self.finger_qpos, self.finger_max, self.cube_qpos = addresses(m)
        self.max_opening = 2 * self.finger_max
        self.cube_dof = m.jnt_dofadr[m.joint("cube").id]
        self.cube_geom = m.geom("cube").id
        self.tcp = m.site("tcp").id
        self.base = m.body("fr5_base").id
        self.pad_geoms = [
            [g for g in range(m.ngeom) if m.geom_bodyid[g] == m.body(pad).id] for pad in PADS
        ]
        self.half_extents = np.array(cube["half_extents"], dtype=float)
        self.table_top = self.settings.table_height
        self.substeps = int(self.settings.substeps) * divisor
        mujoco.mj_forward(m, self.data)
        self.base_pos = self.data.xpos[self.base].copy()
        self.base_rot = self.data.xmat[self.base].reshape(3, 3).copy()
        self.base_quat = self.data.xquat[self.base].copy()
        self._fromto = np.zeros(6)

    @staticmethod
    def _key(cube: dict) -> tuple:
        return (tuple(round(v, 9) for v in cube["half_extents"]), round(cube["mass"], 9), round(cube["friction"], 9))

    def fits(self, cube: dict) -> bool:
        """Whether this model already has `cube`'s size and material."""
        return self._key(cube) == self.cube_key

    def reset(self, home: list[float], cube: dict) -> None:
        """Arm at `home`, gripper open, the cube dropped at its placement, then settled as
        fairgrasp settles a placed object."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[self.arm_qpos] = home
        d.ctrl[:6] = home
        d.qpos[self.finger_qpos] = self.finger_max
        d.ctrl[6] = self.finger_max
        # The gripper's controller: fairgrasp's own model of a MoveGripper, the twin's too.
        from fairgrasp import GripperRamp

        self.gripper = GripperRamp(100.0)
        p = np.array(cube["position"], dtype=float)
        p[2] = cube["rest_z"] + DROP_GAP
        x, y, z, w = cube["orientation_xyzw"]
        world_quat = np.zeros(4)
        mujoco.mju_mulQuat(world_quat, self.base_quat, np.array([w, x, y, z], dtype=float))
        d.qpos[self.cube_qpos : self.cube_qpos + 3] = self.base_pos + self.base_rot @ p
        d.qpos[self.cube_qpos + 3 : self.cube_qpos + 7] = world_quat
        mujoco.mj_forward(m, d)
        max_steps = math.ceil(1.0 / m.opt.timestep)
        for step in range(max_steps):
            mujoco.mj_step(m, d)
            v = d.qvel[self.cube_dof : self.cube_dof + 6]
            if step >= 4 and np.linalg.norm(v[:3]) + 0.05 * np.linalg.norm(v[3:]) < 1e-3:
                break
        d.time = 0.0

    # ── what the controller and the pose feed report ─────────────────────────
    def opening(self) -> float:
        """Distance between the pads (m): the two fingers' positions added. (fairgrasp reads
        twice the left finger's, which its hard mimic coupling makes the same; MuJoCo's
        coupling is a soft joint equality that gives a few mm under the 40 N squeeze, and
        2 × q_left then under-reads the stroke a gripper reports. `--opening left` reads it
        that way, for comparison.)"""
        q = self.data.qpos[self.finger_qpos]
        if OPENING == "left":
            return float(2 * q[0])
        return float(q[0] + q[1])

    def cube_pose(self) -> tuple[np.ndarray, list[float]]:
        """The cube's centre and orientation (xyzw) in the arm base frame."""
        d = self.data
        p = self.base_rot.T @ (d.qpos[self.cube_qpos : self.cube_qpos + 3] - self.base_pos)
        inv, q = np.zeros(4), np.zeros(4)
        mujoco.mju_negQuat(inv, self.base_quat)
        mujoco.mju_mulQuat(q, inv, d.qpos[self.cube_qpos + 3 : self.cube_qpos + 7])
        return p, quat_xyzw(q)

    def readings(self) -> tuple[list[float], list[float], int, list[float], list[float]]:
        """`(joints_deg, joint_speeds_deg, gripper_percent, object_pos, object_quat_xyzw)`."""
        d = self.data
        joints = np.degrees(d.qpos[self.arm_qpos]).tolist()
        speeds = np.degrees(d.qvel[self.arm_dof]).tolist()
        percent = int(min(max(round(self.opening() / self.max_opening * 100), 0), 100))
        p, q = self.cube_pose()
        return joints, speeds, percent, p.tolist(), q

    # ── driving ──────────────────────────────────────────────────────────────
    def drive(self, set_points: list[list[float]], gripper_open: bool) -> None:
        """One control step: each set point held for its share of the physics substeps (as
        fairgrasp's `[control.servo]` spreads them); no set points: the arm holds its last. A
        changed gripper command is a MoveGripper at full speed (the deployment's at speed
        scale 1), its set point moved on every physics step as the twin's controller does."""
        d = self.data
        target = 100.0 if gripper_open else 0.0
        if self.gripper.target != target:
            fingers = self.opening() / self.max_opening * 100.0
            self.gripper.command(fingers, target, self.gripper.full_speed_percent_per_s)
        ticks = max(len(set_points), 1)
        done = 0
        for k in range(1, ticks + 1):
            if set_points:
                d.ctrl[:6] = set_points[k - 1]
            until = self.substeps * k // ticks
            while done < until:
                d.ctrl[6] = self.finger_max * self.gripper.advance(self.model.opt.timestep) / 100.0
                mujoco.mj_step(self.model, d)
                done += 1

    # ── the task's rule, on MuJoCo's own state ───────────────────────────────
    def touching(self, geoms: list[int]) -> bool:
        """Whether any of `geoms` is within fairgrasp's touch distance of the cube."""
        m, d = self.model, self.data
        if hasattr(mujoco, "mj_geomDistance"):
            return any(
                mujoco.mj_geomDistance(m, d, g, self.cube_geom, 2 * TOUCH_DISTANCE, self._fromto) <= TOUCH_DISTANCE
                for g in geoms
            )
        # Without the distance query: the solver's contacts (penetrating ones only).
        pairs = list(zip(d.contact.geom1[: d.ncon], d.contact.geom2[: d.ncon]))
        return any({int(a), int(b)} == {g, self.cube_geom} for a, b in pairs for g in geoms)

    def world(self) -> dict:
        """MuJoCo's own state where the readings were taken, for a trace: the TCP and the
        cube (base frame, m; the cube's orientation xyzw), the pads' distance (m) and which pads
        touch the cube."""
        mujoco.mj_kinematics(self.model, self.data)
        tcp = self.base_rot.T @ (self.data.site_xpos[self.tcp] - self.base_pos)
        cube, quat = self.cube_pose()
        return {
            "tcp": tcp.tolist(),
            "cube": cube.tolist(),
            "cube_quat_xyzw": quat,
            "opening": self.opening(),
            "pads_touch": [self.touching(g) for g in self.pad_geoms],
        }

    def lift(self, rest_z: float) -> float:
        return float(self.cube_pose()[0][2] - rest_z)

    def tcp_distance(self) -> float:
        d = self.data
        return float(np.linalg.norm(d.qpos[self.cube_qpos : self.cube_qpos + 3] - d.site_xpos[self.tcp]))

    def rule(self, gripper_open: bool, rest_z: float, min_lift: float, max_offset: float) -> dict:
        """The task's success conditions on MuJoCo's state now."""
        # Frames of the present positions (mj_step leaves them at the step's start).
        mujoco.mj_kinematics(self.model, self.data)
        pads = [self.touching(g) for g in self.pad_geoms]
        grasped = (not gripper_open) and all(pads) and self.opening() > MIN_OPENING
        lift, distance = self.lift(rest_z), self.tcp_distance()
        return {
            "holds": bool(grasped and lift > min_lift and distance < max_offset),
            "grasped": bool(grasped),
            "lift": lift,
        }

    def off_table(self) -> bool:
        p = self.data.qpos[self.cube_qpos : self.cube_qpos + 3]
        s = self.settings
        return bool(
            p[2] < self.table_top - 2 * self.half_extents[2]
            or abs(p[0] - s.table_center[0]) > s.table_size[0] / 2
            or abs(p[1] - s.table_center[1]) > s.table_size[1] / 2
        )


@dataclass
class Episode:
    seed: int
    success: bool = False
    steps: int = 0
    ended_by: str = "step limit"
    driver_rule_held: bool = False
    max_lift_mm: float = 0.0
    grasped_steps: int = 0
    # Steps where the driver's estimated grasp (inferred pad contacts) disagreed with MuJoCo's.
    grasp_estimate_mismatches: int = 0
    ik_failures: int = 0


def run_episode(driver, cell: MujocoCell, cube: dict, seed: int, trace=None) -> Episode:
    """One episode of the model in the MuJoCo cell (see the module documentation). `trace`: a
    text file that gets each step's `{"obs": [...], "action": [...]}` line, the format of
    `fairgrasp eval --trace`, to set beside fairgrasp's own trace of the same seed, with
    MuJoCo's own state when the readings were taken (`world`, `MujocoCell.world`) and the
    episode's `seed`."""
    min_lift, max_offset = driver.success_rule
    hold = driver.success_hold_steps
    rest_z = cube["rest_z"]
    cell.reset(driver.home_rad, cube)
    e = Episode(seed=seed)
    streak = 0
    grasped = False

    def judge(gripper_open: bool) -> bool:
        nonlocal streak, grasped
        r = cell.rule(gripper_open, rest_z, min_lift, max_offset)
        e.max_lift_mm = max(e.max_lift_mm, r["lift"] * 1000)
        e.grasped_steps += r["grasped"]
        grasped = r["grasped"]
        streak = streak + 1 if r["holds"] else 0
        return streak >= hold

    def record() -> None:
        if trace is not None and (last := driver.last_step()) is not None:
            obs, action = last
            line = {"obs": obs, "action": action, "world": cell.world(), "seed": seed}
            trace.write(json.dumps(line) + "\n")

    set_points, gripper_open, _ = driver.begin(*cell.readings())
    record()
    for step in range(driver.max_steps):
        if step > 0:
            set_points, gripper_open, held = driver.step(*cell.readings())
            e.grasp_estimate_mismatches += driver.estimate()["grasped"] != grasped
            if held:
                # The deployment stops acting here and holds the arm at its last target with the
                # gripper as commanded for `hold_after_success` steps before it ends the
                # episode; MuJoCo's rule may complete its streak meanwhile, as the twin's does.
                e.driver_rule_held = True
                e.ended_by = "driver's success rule"
                for _ in range(driver.hold_after_success):
                    cell.drive(driver.hold(), gripper_open)
                    if judge(gripper_open):
                        e.success = True
                        break
                break
            record()
        cell.drive(set_points, gripper_open)
        e.steps = step + 1
        if judge(gripper_open):
            e.success, e.ended_by = True, "success"
            break
        if cell.off_table():
            e.ended_by = "cube off the table"
            break
    e.ik_failures = driver.ik_failures
    return e


def ours(model: str, episodes: int, seed: int, binary: str | None) -> dict:
    """fairgrasp's own held-out success over the same seeds: `fairgrasp.evaluate` (the Python
    face of `fairgrasp eval`), or `BINARY eval --json`."""
    if binary:
        out = subprocess.run(
            [binary, "eval", "--model", model, "--episodes", str(episodes), "--seed", str(seed), "--json"],
            capture_output=True, text=True, check=True,
        ).stdout
        line = next(l for l in reversed(out.splitlines()) if l.startswith("{"))
        return json.loads(line)
    import fairgrasp

    return fairgrasp.evaluate(model, episodes=episodes, seed=seed)


def cpu_model() -> str:
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="bench/sim2sim",
        description="A saved fairgrasp model in the MuJoCo cell, through fairgrasp's deployment "
        "code, beside its success in fairgrasp's own simulator over the same seeds.",
    )
    parser.add_argument("--model", required=True, help="model directory (runs/NAME/best) or run directory")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=HELD_OUT_SEED, help="first episode seed (default: the held-out range)")
    parser.add_argument("--json", action="store_true", help="print the result as one JSON line as well")
    parser.add_argument("--out", help="write the full result (every episode) as JSON here")
    parser.add_argument("--no-ours", action="store_true", help="skip fairgrasp's own evaluation")
    parser.add_argument("--fairgrasp-bin", help="run fairgrasp's evaluation with this binary (`eval --json`) instead of fairgrasp.evaluate")
    parser.add_argument("-v", "--verbose", action="store_true", help="a line per episode")
    parser.add_argument(
        "--trace", help="write every step's observation and action as JSON lines here (`fairgrasp eval --trace`'s format, "
        "with MuJoCo's TCP, cube pose, opening and pad contacts under `world` and the episode's `seed`)",
    )
    parser.add_argument(
        "--opening", choices=["both", "left"], default="both",
        help="read the gripper's opening as q_left + q_right (default: the pads' distance) or as 2 x q_left",
    )
    parser.add_argument(
        "--timestep-divisor", type=int, default=1,
        help="diagnostic: MuJoCo at dt / N with contact time constants 2 x its step (stiffer contacts); default 1, the cell's rate",
    )
    args = parser.parse_args(argv)
    global OPENING
    OPENING = args.opening
    if args.timestep_divisor < 1:
        parser.error("--timestep-divisor must be at least 1")
    if args.episodes < 1:
        parser.error("--episodes must be at least 1")

    import fairgrasp

    started = time.monotonic()
    driver = fairgrasp.PolicyDriver(args.model)
    config = tomllib.loads(driver.config_toml())
    cell: MujocoCell | None = None
    results: list[Episode] = []
    trace = open(args.trace, "w") if args.trace else None
    for i in range(args.episodes):
        seed = args.seed + i
        cube = driver.placement(seed)
        if cell is None or not cell.fits(cube):
            cell = MujocoCell(config, cube, divisor=args.timestep_divisor)
        e = run_episode(driver, cell, cube, seed, trace)
        results.append(e)
        if args.verbose:
            print(
                f"episode {i + 1} (seed {seed}): {'grasped' if e.success else 'failed'} after {e.steps} steps "
                f"({e.ended_by}; max lift {e.max_lift_mm:.0f} mm)",
                flush=True,
            )
    if trace is not None:
        trace.close()
    mujoco_seconds = time.monotonic() - started
    n = len(results)
    wins = sum(e.success for e in results)
    summary = {
        "model": os.fspath(args.model),
        "episodes": n,
        "seed": args.seed,
        "mujoco": {
            "successes": wins,
            "success_rate": wins / n,
            "mean_steps": sum(e.steps for e in results) / n,
            "ended_by_driver_rule": sum(e.driver_rule_held for e in results),
            "driver_rule_without_mujoco_success": sum(e.driver_rule_held and not e.success for e in results),
            "ik_failures": sum(e.ik_failures for e in results),
            "grasp_estimate_mismatch_steps": sum(e.grasp_estimate_mismatches for e in results),
            "failures_by_end": {
                end: sum(1 for e in results if not e.success and e.ended_by == end)
                for end in sorted({e.ended_by for e in results if not e.success})
            },
            "seconds": round(mujoco_seconds, 1),
            "version": mujoco.__version__,
        },
        "driver": {
            "control_period": driver.control_period,
            "servo_ticks": driver.servo_ticks,
            "motion_mismatch": driver.motion_mismatch,
            "observation_mismatch": driver.observation_mismatch,
        },
        "opening_read_as": args.opening,
        "timestep_divisor": args.timestep_divisor,
        "cpu": cpu_model(),
    }
    line = f"MuJoCo {wins}/{n} ({100 * wins / n:.1f} %)"
    if not args.no_ours:
        started = time.monotonic()
        result = ours(os.fspath(args.model), n, args.seed, args.fairgrasp_bin)
        rate = float(result["success_rate"])
        k = round(rate * n)
        summary["fairgrasp"] = {
            "successes": k,
            "success_rate": rate,
            "mean_length": result.get("mean_length"),
            "seconds": round(time.monotonic() - started, 1),
            "via": args.fairgrasp_bin or "fairgrasp.evaluate",
        }
        line += f", fairgrasp {k}/{n} ({100 * rate:.1f} %)"
    print(line)
    print(
        f"  MuJoCo: mean {summary['mujoco']['mean_steps']:.1f} steps; the driver's own success rule ended "
        f"{summary['mujoco']['ended_by_driver_rule']} episodes ({summary['mujoco']['driver_rule_without_mujoco_success']} "
        f"of them without success in MuJoCo); {summary['mujoco']['ik_failures']} IK failures; "
        f"{summary['mujoco']['grasp_estimate_mismatch_steps']} steps where the estimated grasp differed from MuJoCo's"
    )
    if summary["mujoco"]["failures_by_end"]:
        print(f"  MuJoCo failures by how they ended: {summary['mujoco']['failures_by_end']}")
    for note in (driver.motion_mismatch, driver.observation_mismatch):
        if note:
            print(f"  note: {note}")
    if args.out:
        Path(args.out).write_text(json.dumps({**summary, "episodes_detail": [asdict(e) for e in results]}, indent=1))
    if args.json:
        print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
