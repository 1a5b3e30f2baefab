"""The grasp scene in MuJoCo: the bundled FR5 and parallel gripper, the table and the cube, built
from the same URDF files and `configs/env.toml` settings as fairgrasp's simulator and the PyBullet
reference, for the physics comparison in `bench/run`.

The MJCF is generated here from the URDFs (links → bodies, joints → hinges and slides, collision
primitives → geoms, the mimic finger → a joint equality), because MuJoCo's own URDF import drops
what the comparison needs: capsules, the mimic joint, actuators and contact settings.

Settings carried over: 240 Hz, gravity, PD position drives with our gains (arm kp 8000, kd 400,
armature 0.1; fingers kp 2000, kd 40, 40 N), URDF joint damping and effort limits, table, cube
mass and friction, pad friction, no self-collision. Contacts: MuJoCo's default soft contacts let
the squeezed cube slip out, so contacts are stiff (solref time constant 2·dt, solimp 0.99) like
rapier's 300 Hz contact frequency; MuJoCo takes the larger friction of a pair where rapier averages.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np

from .scene import ARM_JOINTS, TABLE_THICKNESS, SceneSettings, load_env_config, repo_root

FINGER = "left_finger_joint"
MIMIC = "right_finger_joint"


def rpy_quat(rpy: list[float]) -> list[float]:
    """URDF roll-pitch-yaw (fixed axes X, Y, Z) as a MuJoCo quaternion (w, x, y, z)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (math.cos(r / 2), math.sin(r / 2), math.cos(p / 2), math.sin(p / 2), math.cos(y / 2), math.sin(y / 2))
    return [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ]


def floats(text: str | None, default: str) -> list[float]:
    return [float(v) for v in (text or default).split()]


def fmt(values) -> str:
    return " ".join(f"{v:.9g}" for v in values)


def origin_attrs(element: ET.Element | None) -> dict[str, str]:
    xyz = floats(element.get("xyz") if element is not None else None, "0 0 0")
    rpy = floats(element.get("rpy") if element is not None else None, "0 0 0")
    return {"pos": fmt(xyz), "quat": fmt(rpy_quat(rpy))}


def geom_attrs(geometry: ET.Element) -> dict[str, str] | None:
    shape = geometry[0]
    if shape.tag == "box":
        return {"type": "box", "size": fmt(v / 2 for v in floats(shape.get("size"), ""))}
    if shape.tag == "cylinder":
        return {"type": "cylinder", "size": fmt([float(shape.get("radius")), float(shape.get("length")) / 2])}
    if shape.tag == "capsule":
        return {"type": "capsule", "size": fmt([float(shape.get("radius")), float(shape.get("length")) / 2])}
    if shape.tag == "sphere":
        return {"type": "sphere", "size": shape.get("radius")}
    return None  # meshes: the bundled descriptions use primitives only


def addresses(m: mujoco.MjModel) -> tuple[list[int], list[int], list[int], float, int]:
    """Where the cell's state lives in `qpos`/`qvel`: the arm joints' positions and velocities,
    the two fingers' positions, the driven finger's stroke and the cube's free joint."""
    arm_qpos = [m.jnt_qposadr[m.joint(n).id] for n in ARM_JOINTS]
    arm_dof = [m.jnt_dofadr[m.joint(n).id] for n in ARM_JOINTS]
    finger_qpos = [m.jnt_qposadr[m.joint(n).id] for n in (FINGER, MIMIC)]
    finger_max = float(m.jnt_range[m.joint(FINGER).id][1])
    cube_qpos = m.jnt_qposadr[m.joint("cube").id]
    return arm_qpos, arm_dof, finger_qpos, finger_max, cube_qpos


def mjcf(settings: SceneSettings, config: dict, root: Path | None = None) -> str:
    """The MJCF text of the scene."""
    root = root or repo_root()
    s = settings
    scene = config["scene"]
    arm_cfg, grip_cfg = scene["arm"], scene["gripper"]
    arm = ET.parse(root / "assets/robots/fr5/urdf/fr5.urdf").getroot()
    gripper = ET.parse(root / "assets/grippers/parallel/urdf/parallel_gripper.urdf").getroot()
    links = {l.get("name"): l for l in [*arm.findall("link"), *gripper.findall("link")]}
    joints = [*arm.findall("joint"), *gripper.findall("joint")]
    children: dict[str, list[ET.Element]] = {}
    for j in joints:
        children.setdefault(j.find("parent").get("link"), []).append(j)
    # The gripper's root link hangs off the flange by the configured mount.
    mount = ET.Element("joint", name="gripper_mount", type="fixed")
    ET.SubElement(mount, "parent", link=s.flange_link)
    ET.SubElement(mount, "child", link=gripper.find("link").get("name"))
    ET.SubElement(mount, "origin", xyz=fmt(arm_cfg["gripper_mount"]["xyz"]), rpy=fmt(arm_cfg["gripper_mount"]["rpy"]))
    children.setdefault(s.flange_link, []).append(mount)

    dt = s.dt
    solref = f"{2 * dt:.6g} 1"
    solimp = "0.99 0.99 0.001"
    model = ET.Element("mujoco", model="fa_arm_grasp")
    ET.SubElement(model, "compiler", angle="radian", inertiafromgeom="false", autolimits="true")
    ET.SubElement(model, "option", timestep=f"{dt:.9g}", gravity=f"0 0 {-s.gravity}", integrator="implicitfast", solver="Newton")
    default = ET.SubElement(model, "default")
    ET.SubElement(default, "geom", solref=solref, solimp=solimp)
    world = ET.SubElement(model, "worldbody")
    hx, hy = s.table_size[0] / 2, s.table_size[1] / 2
    ET.SubElement(
        world, "geom", name="table", type="box", size=fmt([hx, hy, TABLE_THICKNESS / 2]),
        pos=fmt([s.table_center[0], s.table_center[1], s.table_height - TABLE_THICKNESS / 2]),
        friction=f"{s.table_friction} 0.005 0.0001", contype="1", conaffinity="3",
    )

    def add_body(parent: ET.Element, link_name: str, attrs: dict[str, str]) -> None:
        body = ET.SubElement(parent, "body", name=link_name, **attrs)
        link = links[link_name]
        inertial = link.find("inertial")
        if inertial is not None:
            i = inertial.find("inertia")
            g = {k: float(i.get(k, "0")) for k in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")}
            tensor = np.array([[g["ixx"], g["ixy"], g["ixz"]], [g["ixy"], g["iyy"], g["iyz"]], [g["ixz"], g["iyz"], g["izz"]]])
            origin = inertial.find("origin")
            rot = np.zeros(9)
            mujoco.mju_quat2Mat(rot, np.array(rpy_quat(floats(origin.get("rpy") if origin is not None else None, "0 0 0"))))
            rot = rot.reshape(3, 3)
            tensor = rot @ tensor @ rot.T  # in the link frame
            full = [tensor[0, 0], tensor[1, 1], tensor[2, 2], tensor[0, 1], tensor[0, 2], tensor[1, 2]]
            o = origin_attrs(origin)
            ET.SubElement(body, "inertial", pos=o["pos"], mass=inertial.find("mass").get("value"), fullinertia=fmt(full))
        for c in link.findall("collision"):
            g = geom_attrs(c.find("geometry"))
            if g is None:
                continue
            friction = s.pad_friction if link_name in ("left_finger", "right_finger") else 0.8
            ET.SubElement(body, "geom", **g, **origin_attrs(c.find("origin")), friction=f"{friction} 0.005 0.0001", contype="2", conaffinity="1")
        if link_name == "tcp":
            ET.SubElement(body, "site", name="tcp", pos="0 0 0")
        for j in children.get(link_name, []):
            child = j.find("child").get("link")
            jt = j.get("type")
            child_attrs = origin_attrs(j.find("origin"))
            if jt == "fixed":
                add_body(body, child, child_attrs)
                continue
            add_body(body, child, child_attrs)
            child_body = body.find(f"body[@name='{child}']")
            limit = j.find("limit")
            dyn = j.find("dynamics")
            joint = ET.Element(
                "joint", name=j.get("name"), type="hinge" if jt in ("revolute", "continuous") else "slide",
                axis=fmt(floats(j.find("axis").get("xyz") if j.find("axis") is not None else None, "1 0 0")),
            )
            if limit is not None and jt != "continuous":
                joint.set("range", fmt([float(limit.get("lower")), float(limit.get("upper"))]))
            if dyn is not None:
                joint.set("damping", dyn.get("damping", "0"))
            if j.get("name") in ARM_JOINTS:
                joint.set("armature", str(arm_cfg["armature"]))
            child_body.insert(0, joint)

    base = ET.SubElement(world, "body", name="fr5_base", pos=fmt(s.base_xyz), quat=fmt(rpy_quat([0, 0, s.base_yaw])))
    arm_root = arm.find("link").get("name")
    add_body(base, arm_root, {})

    h = s.object_size / 2
    cube = ET.SubElement(world, "body", name="cube", pos=fmt([s.placement_center[0], s.placement_center[1], s.table_height + h]))
    ET.SubElement(cube, "freejoint", name="cube")
    inertia = s.object_mass * s.object_size**2 / 6
    ET.SubElement(cube, "inertial", pos="0 0 0", mass=str(s.object_mass), diaginertia=fmt([inertia] * 3))
    ET.SubElement(cube, "geom", type="box", size=fmt([h, h, h]), friction=f"{s.object_friction} 0.005 0.0001", contype="1", conaffinity="3")

    actuators = ET.SubElement(model, "actuator")
    efforts = {j.get("name"): float(j.find("limit").get("effort")) for j in joints if j.find("limit") is not None}
    for name in ARM_JOINTS:
        e = efforts[name]
        ET.SubElement(actuators, "position", name=name, joint=name, kp=str(arm_cfg["kp"]), kv=str(arm_cfg["kd"]), forcerange=fmt([-e, e]))
    f = grip_cfg["force_limit"]
    ET.SubElement(actuators, "position", name="gripper", joint=FINGER, kp=str(grip_cfg["kp"]), kv=str(grip_cfg["kd"]), forcerange=fmt([-f, f]))
    equality = ET.SubElement(model, "equality")
    ET.SubElement(equality, "joint", joint1=MIMIC, joint2=FINGER, polycoef="0 1 0 0 0", solref=solref)
    return ET.tostring(model, encoding="unicode")


class MujocoGraspScene:
    """FR5 + gripper + table + cube in MuJoCo, with a scripted grasp to reach the held state."""

    def __init__(self, config: dict | None = None, root: Path | None = None) -> None:
        self.config = config or load_env_config()
        self.settings = SceneSettings.from_config(self.config)
        self.model = mujoco.MjModel.from_xml_string(mjcf(self.settings, self.config, root))
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.arm_qpos, self.arm_dof, self.finger_qpos, self.finger_max, self.cube_qpos = addresses(m)
        self.tcp = m.site("tcp").id
        self.reset()

    def reset(self) -> None:
        d, s = self.data, self.settings
        mujoco.mj_resetData(self.model, d)
        d.qpos[self.arm_qpos] = s.home
        d.qpos[self.finger_qpos] = self.finger_max
        d.ctrl[:6] = s.home
        d.ctrl[6] = self.finger_max
        mujoco.mj_forward(self.model, d)

    def step(self, n: int = 1) -> None:
        mujoco.mj_step(self.model, self.data, nstep=n)

    def cube_height(self) -> float:
        """Cube centre above the table top."""
        return float(self.data.qpos[self.cube_qpos + 2] - self.settings.table_height)

    def ik(self, target: np.ndarray, rotation: np.ndarray, q0: np.ndarray) -> np.ndarray:
        """Arm joints putting the TCP at `target` with `rotation` (damped least squares on a
        scratch copy of the state)."""
        m = self.model
        d = mujoco.MjData(m)
        d.qpos[:] = self.data.qpos
        d.qpos[self.arm_qpos] = q0
        jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        want = np.zeros(4)
        mujoco.mju_mat2Quat(want, rotation.flatten())
        for _ in range(200):
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            have = np.zeros(4)
            mujoco.mju_mat2Quat(have, d.site_xmat[self.tcp])
            local = np.zeros(3)
            mujoco.mju_subQuat(local, want, have)  # in the TCP's frame
            err_rot = d.site_xmat[self.tcp].reshape(3, 3) @ local
            err = np.concatenate([target - d.site_xpos[self.tcp], err_rot])
            if np.linalg.norm(err) < 1e-6:
                break
            mujoco.mj_jacSite(m, d, jacp, jacr, self.tcp)
            jac = np.vstack([jacp, jacr])[:, self.arm_dof]
            dq = jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), err)
            d.qpos[self.arm_qpos] += dq
        return d.qpos[self.arm_qpos].copy()

    def move(self, q_target: np.ndarray, steps: int) -> None:
        """Ramps the arm's position targets to `q_target` over `steps` physics steps."""
        start = self.data.ctrl[:6].copy()
        for k in range(1, steps + 1):
            self.data.ctrl[:6] = start + (q_target - start) * (k / steps)
            self.step()

    def scripted_grasp(self, lift: float = 0.15) -> bool:
        """Above the cube, down, close, lift: whether the cube is held `lift` up after a second."""
        self.reset()
        self.step(120)
        d = self.data
        cube = d.qpos[self.cube_qpos : self.cube_qpos + 3].copy()
        rotation = d.site_xmat[self.tcp].reshape(3, 3).copy()  # home: pointing down
        q = d.qpos[self.arm_qpos].copy()
        above = self.ik(cube + [0, 0, 0.12], rotation, q)
        self.move(above, 240)
        at = self.ik(cube, rotation, above)
        self.move(at, 240)
        d.ctrl[6] = 0.0
        self.step(120)
        up = self.ik(cube + [0, 0, lift], rotation, at)
        self.move(up, 240)
        self.step(240)
        return self.cube_height() > lift * 0.8
