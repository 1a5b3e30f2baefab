"""The grasp scene in PyBullet: the bundled FR5 with the parallel gripper on its flange, the table
and the cube, built from the same files and settings as fairgrasp's simulator.

Every figure comes from `configs/env.toml` (fairgrasp's defaults), so the two engines simulate
the same scene: change a setting there and both follow.
"""

from __future__ import annotations

import math
import os
import tempfile
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

try:
    import pybullet as p
    from pybullet_utils import bullet_client
except ImportError:  # The MuJoCo cell (mujoco_scene, sim2sim) reads the settings without it.
    p = bullet_client = None

ARM_JOINTS = ["j1", "j2", "j3", "j4", "j5", "j6"]
FINGER_JOINTS = ["left_finger_joint", "right_finger_joint"]
PAD_LINKS = ["left_finger", "right_finger"]
TCP_LINK = "tcp"
TABLE_THICKNESS = 0.05  # as in fairgrasp's scene


def repo_root() -> Path:
    """The fairgrasp checkout: `FAIRGRASP_ROOT`, else three levels above this file."""
    env = os.environ.get("FAIRGRASP_ROOT")
    return Path(env) if env else Path(__file__).resolve().parents[3]


def load_env_config(path: Path | None = None) -> dict:
    """fairgrasp's environment defaults (`configs/env.toml`)."""
    path = path or repo_root() / "configs" / "env.toml"
    with open(path, "rb") as f:
        return tomllib.load(f)


def combined_urdf(arm_urdf: Path, gripper_urdf: Path, flange_link: str) -> str:
    """One URDF with the gripper bolted on the arm's flange by a fixed joint (fairgrasp attaches
    it the same way; PyBullet then treats arm and gripper as one multibody, with no constraint
    drift between them)."""
    arm = ET.parse(arm_urdf).getroot()
    gripper = ET.parse(gripper_urdf).getroot()
    names = {link.get("name") for link in arm.findall("link")}
    if flange_link not in names:
        raise ValueError(f"{arm_urdf}: no link named {flange_link!r} to mount the gripper on")
    gripper_root = gripper.find("link").get("name")
    for child in gripper:
        arm.append(child)
    # PyBullet gives a link without <inertial> 1 kg and unit inertia; fairgrasp merges such frame
    # links (tool0, tcp) into their parent. A negligible mass keeps them out of the dynamics.
    for link in arm.findall("link"):
        if link.find("inertial") is None:
            inertial = ET.SubElement(link, "inertial")
            ET.SubElement(inertial, "mass", value="1e-6")
            ET.SubElement(
                inertial, "inertia", ixx="1e-9", ixy="0", ixz="0", iyy="1e-9", iyz="0", izz="1e-9"
            )
    mount = ET.SubElement(arm, "joint", name="gripper_mount", type="fixed")
    ET.SubElement(mount, "parent", link=flange_link)
    ET.SubElement(mount, "child", link=gripper_root)
    ET.SubElement(mount, "origin", xyz="0 0 0", rpy="0 0 0")
    return ET.tostring(arm, encoding="unicode")


@dataclass
class SceneSettings:
    dt: float
    substeps: int
    gravity: float
    table_height: float
    table_size: tuple[float, float]
    table_center: tuple[float, float]
    table_friction: float
    object_size: float
    object_mass: float
    object_friction: float
    placement_center: tuple[float, float]
    placement_size: tuple[float, float]
    yaw_range: float
    gripper_force: float
    pad_friction: float
    base_xyz: tuple[float, float, float]
    base_yaw: float
    home: list[float]
    flange_link: str

    @classmethod
    def from_config(cls, config: dict) -> "SceneSettings":
        s = config["scene"]
        # The reference simulates the task's one cube: the first configured object, a box.
        cube = s["objects"][0]
        if cube["shape"]["kind"] != "box":
            raise ValueError("the reference scene needs scene.objects[0] to be a box")
        return cls(
            dt=s["physics"]["dt"],
            substeps=s["physics"]["substeps"],
            gravity=s["physics"]["gravity"],
            table_height=s["table"]["height"],
            table_size=tuple(s["table"]["size"]),
            table_center=tuple(s["table"]["center"]),
            table_friction=s["table"]["friction"],
            object_size=cube["shape"]["size"][0],
            object_mass=cube["mass"],
            object_friction=cube["friction"],
            placement_center=tuple(s["placement"]["center"]),
            placement_size=tuple(s["placement"]["size"]),
            yaw_range=s["placement"]["yaw_range"],
            gripper_force=s["gripper"]["force_limit"],
            pad_friction=s["gripper"]["pad_friction"],
            base_xyz=tuple(s["arm"]["base_xyz"]),
            base_yaw=s["arm"]["base_yaw"],
            home=list(s["arm"]["home"]),
            flange_link=s["arm"]["flange_link"],
        )


class GraspScene:
    """FR5 + gripper + table + cube in one PyBullet DIRECT client of its own."""

    def __init__(self, settings: SceneSettings, root: Path | None = None):
        if p is None:
            raise ImportError("the PyBullet reference needs pybullet (bench/reference/requirements.txt)")
        root = root or repo_root()
        self.settings = s = settings
        self.client = bullet_client.BulletClient(connection_mode=p.DIRECT)
        c = self.client
        c.setGravity(0, 0, -s.gravity)
        c.setTimeStep(s.dt)

        urdf = combined_urdf(
            root / "assets/robots/fr5/urdf/fr5.urdf",
            root / "assets/grippers/parallel/urdf/parallel_gripper.urdf",
            s.flange_link,
        )
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "fr5_with_gripper.urdf"
            path.write_text(urdf)
            self.base_orn = c.getQuaternionFromEuler([0, 0, s.base_yaw])
            self.robot = c.loadURDF(
                str(path),
                basePosition=s.base_xyz,
                baseOrientation=self.base_orn,
                useFixedBase=True,
                flags=p.URDF_USE_INERTIA_FROM_FILE,
            )
        self.base_pos = tuple(s.base_xyz)

        joints = {}
        links = {}
        for j in range(c.getNumJoints(self.robot)):
            info = c.getJointInfo(self.robot, j)
            joints[info[1].decode()] = (j, info)
            links[info[12].decode()] = j
        self.arm = [joints[n][0] for n in ARM_JOINTS]
        self.arm_limits = np.array([(joints[n][1][8], joints[n][1][9]) for n in ARM_JOINTS])
        self.arm_efforts = [joints[n][1][10] for n in ARM_JOINTS]
        self.fingers = [joints[n][0] for n in FINGER_JOINTS]
        self.finger_max = joints[FINGER_JOINTS[0]][1][9]
        self.pads = [links[n] for n in PAD_LINKS]
        self.tcp = links[TCP_LINK]

        # Friction as in fairgrasp: robot links 0.8, finger pads higher. (PyBullet multiplies
        # the two bodies' coefficients of a contact, rapier averages them: same inputs, each
        # engine's own rule.)
        for link in [-1, *range(c.getNumJoints(self.robot))]:
            c.changeDynamics(self.robot, link, lateralFriction=0.8)
        for pad in self.pads:
            c.changeDynamics(self.robot, pad, lateralFriction=s.pad_friction)

        # Table: a fixed box whose top is at `table_height`.
        half = [s.table_size[0] / 2, s.table_size[1] / 2, TABLE_THICKNESS / 2]
        self.table = c.createMultiBody(
            baseMass=0,
            baseCollisionShapeIndex=c.createCollisionShape(p.GEOM_BOX, halfExtents=half),
            baseVisualShapeIndex=c.createVisualShape(
                p.GEOM_BOX, halfExtents=half, rgbaColor=[0.6, 0.5, 0.4, 1]
            ),
            basePosition=[s.table_center[0], s.table_center[1], s.table_height - half[2]],
        )
        c.changeDynamics(self.table, -1, lateralFriction=s.table_friction)

        # The cube, created once and moved at every reset.
        h = s.object_size / 2
        self.object = c.createMultiBody(
            baseMass=s.object_mass,
            baseCollisionShapeIndex=c.createCollisionShape(p.GEOM_BOX, halfExtents=[h, h, h]),
            baseVisualShapeIndex=c.createVisualShape(
                p.GEOM_BOX, halfExtents=[h, h, h], rgbaColor=[0.1, 0.6, 0.9, 1]
            ),
            basePosition=[s.placement_center[0], s.placement_center[1], self.rest_height()],
        )
        c.changeDynamics(self.object, -1, lateralFriction=s.object_friction)

        self.set_arm_positions(s.home)
        self.set_gripper_opening_now(self.max_opening())
        self.set_arm_targets(s.home)
        self.set_gripper_open(True)
        c.stepSimulation()
        self.home_state = c.saveState()
        self.home_tcp_yaw = self.tcp_yaw()

    # ── geometry ───────────────────────────────────────────────────────────

    def table_top(self) -> float:
        return self.settings.table_height

    def rest_height(self) -> float:
        return self.settings.table_height + self.settings.object_size / 2

    def max_opening(self) -> float:
        return 2 * self.finger_max

    def to_base(self, pos, orn=(0, 0, 0, 1)):
        """A world pose in the arm base frame."""
        inv_pos, inv_orn = self.client.invertTransform(self.base_pos, self.base_orn)
        return self.client.multiplyTransforms(inv_pos, inv_orn, pos, orn)

    # ── state ──────────────────────────────────────────────────────────────

    def arm_positions(self) -> np.ndarray:
        return np.array([s[0] for s in self.client.getJointStates(self.robot, self.arm)])

    def gripper_opening(self) -> float:
        return 2 * self.client.getJointState(self.robot, self.fingers[0])[0]

    def tcp_state(self):
        """(position, quaternion xyzw, linear velocity) of the TCP frame, world."""
        s = self.client.getLinkState(
            self.robot, self.tcp, computeLinkVelocity=1, computeForwardKinematics=1
        )
        return s[4], s[5], s[6]

    def tcp_yaw(self) -> float:
        return self.client.getEulerFromQuaternion(self.tcp_state()[1])[2]

    def object_pose(self):
        return self.client.getBasePositionAndOrientation(self.object)

    def pad_contacts(self) -> list[bool]:
        return [
            len(self.client.getContactPoints(self.robot, self.object, linkIndexA=pad)) > 0
            for pad in self.pads
        ]

    def object_off_table(self) -> bool:
        s = self.settings
        x, y, z = self.object_pose()[0]
        return (
            z < s.table_height - s.object_size
            or abs(x - s.table_center[0]) > s.table_size[0] / 2
            or abs(y - s.table_center[1]) > s.table_size[1] / 2
        )

    # ── commands ───────────────────────────────────────────────────────────

    def set_arm_positions(self, q) -> None:
        for j, v in zip(self.arm, q):
            self.client.resetJointState(self.robot, j, v, 0.0)

    def set_gripper_opening_now(self, opening: float) -> None:
        for j in self.fingers:
            self.client.resetJointState(self.robot, j, opening / 2, 0.0)

    def set_arm_targets(self, q) -> None:
        """PD position control at the URDF effort limits (PyBullet's POSITION_CONTROL)."""
        self.client.setJointMotorControlArray(
            self.robot, self.arm, p.POSITION_CONTROL, targetPositions=list(q),
            forces=self.arm_efforts,
        )

    def set_gripper_open(self, open_: bool) -> None:
        # PyBullet ignores URDF <mimic>: both fingers get the same target and force limit.
        target = self.finger_max if open_ else 0.0
        self.gripper_target = 2 * target
        self.client.setJointMotorControlArray(
            self.robot, self.fingers, p.POSITION_CONTROL, targetPositions=[target, target],
            forces=[self.settings.gripper_force] * 2,
        )

    def step_control(self) -> None:
        for _ in range(self.settings.substeps):
            self.client.stepSimulation()

    # ── reset ──────────────────────────────────────────────────────────────

    def reset(self, rng: np.random.Generator) -> None:
        """Home pose, gripper open, the cube placed at random and settled (as fairgrasp does:
        uniform in the placement area, uniform yaw, redrawn if it would touch the robot)."""
        c = self.client
        s = self.settings
        c.restoreState(self.home_state)
        self.set_arm_targets(s.home)
        self.set_gripper_open(True)
        for _ in range(100):
            lx = s.placement_center[0] + (rng.random() - 0.5) * s.placement_size[0]
            ly = s.placement_center[1] + (rng.random() - 0.5) * s.placement_size[1]
            yaw = (rng.random() * 2 - 1) * s.yaw_range
            pos, _ = c.multiplyTransforms(self.base_pos, self.base_orn, [lx, ly, 0], [0, 0, 0, 1])
            orn = c.getQuaternionFromEuler([0, 0, yaw + s.base_yaw])
            c.resetBasePositionAndOrientation(
                self.object, [pos[0], pos[1], self.rest_height() + 0.001], orn
            )
            c.resetBaseVelocity(self.object, [0, 0, 0], [0, 0, 0])
            c.performCollisionDetection()
            if not c.getClosestPoints(self.object, self.robot, distance=0.0):
                break
        else:
            raise RuntimeError("no collision-free placement found in 100 draws; check the area")
        self.settle()

    def settle(self) -> None:
        """Steps until the cube rests (speed below 1 mm/s), at most one simulated second."""
        for i in range(int(math.ceil(1.0 / self.settings.dt))):
            self.client.stepSimulation()
            v, w = self.client.getBaseVelocity(self.object)
            speed = np.linalg.norm(v) + np.linalg.norm(w) * 0.05
            if i >= 4 and speed < 1e-3:
                break

    def close(self) -> None:
        self.client.disconnect()
