"""The PAPRAS URDF's joints as plain kinematics: ``T_parent_child`` of each joint at a joint value.

Both viewers animate the arm the same way (a transform per joint, named by its parent and child link),
so the joint maths lives here once: origin (xyz, rpy) then the motion about/along the axis; mimic joints
(the gripper fingers) follow their driver. Fixed joints are included (their transform never changes).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from services.arm.robot import URDF_PATH


@dataclass(frozen=True)
class UrdfJoint:
    name: str
    kind: str  # revolute, continuous, prismatic, fixed
    parent: str
    child: str
    origin: np.ndarray  # 4x4, parent link -> joint frame at zero
    axis: np.ndarray  # unit 3-vector in the joint frame
    mimic: tuple[str, float, float] | None = None  # (driver joint, multiplier, offset)

    def transform(self, value: float) -> np.ndarray:
        """``T_parent_child`` at ``value`` (rad or m; ignored for fixed joints)."""
        T = self.origin.copy()
        if self.kind in ("revolute", "continuous"):
            M = np.eye(4)
            M[:3, :3] = Rotation.from_rotvec(self.axis * float(value)).as_matrix()
            T = T @ M
        elif self.kind == "prismatic":
            M = np.eye(4)
            M[:3, 3] = self.axis * float(value)
            T = T @ M
        return T


def _origin(el: ET.Element | None) -> np.ndarray:
    T = np.eye(4)
    if el is not None:
        xyz = [float(v) for v in el.get("xyz", "0 0 0").split()]
        rpy = [float(v) for v in el.get("rpy", "0 0 0").split()]
        T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()  # URDF: fixed axes roll, pitch, yaw
        T[:3, 3] = xyz
    return T


def load_joints(path: str | Path = URDF_PATH) -> list[UrdfJoint]:
    """Every joint of the URDF, in file order (parents before children in the PAPRAS file)."""
    root = ET.parse(path).getroot()
    joints = []
    for j in root.iter("joint"):
        if j.get("type") is None or j.find("parent") is None:
            continue  # <joint> elements inside <transmission> only name a joint
        axis_el = j.find("axis")
        axis = np.array([float(v) for v in (axis_el.get("xyz") if axis_el is not None else "1 0 0").split()])
        mimic_el = j.find("mimic")
        mimic = None if mimic_el is None else (mimic_el.get("joint", ""), float(mimic_el.get("multiplier", "1")),
                                               float(mimic_el.get("offset", "0")))
        joints.append(UrdfJoint(name=j.get("name", ""), kind=j.get("type", "fixed"),
                                parent=j.find("parent").get("link"), child=j.find("child").get("link"),
                                origin=_origin(j.find("origin")),
                                axis=axis / (np.linalg.norm(axis) or 1.0), mimic=mimic))
    return joints


def joint_transforms(joints: list[UrdfJoint], names: list[str], q: np.ndarray,
                     *, include_fixed: bool = False) -> list[tuple[UrdfJoint, np.ndarray]]:
    """(joint, T_parent_child) for every movable joint (and fixed ones when asked); unknown joints at 0."""
    values = {n: float(v) for n, v in zip(names, np.asarray(q, dtype=np.float64), strict=False)}
    out = []
    for j in joints:
        if j.kind == "fixed" and not include_fixed:
            continue
        if j.mimic is not None:
            driver, mult, offset = j.mimic
            value = values.get(driver, 0.0) * mult + offset
        else:
            value = values.get(j.name, 0.0)
        out.append((j, j.transform(value)))
    return out
