"""The hand-eye result in the forms a ROS 2 system loads: a URDF joint and a static transform.

``objscan calibrate hand-eye --out calibration/hand_eye.json`` writes beside the JSON file:

- ``hand_eye.urdf.xml``: a fixed joint ``gripper -> camera`` with the calibrated origin. It replaces the PAPRAS
  URDF's ``objscan/camera_optical_joint`` (``services/arm/robot/papras_6dof.urdf``), so ``camera`` keeps one
  parent and ``robot_state_publisher`` puts the camera where it really is;
- ``hand_eye.tf_static.yaml``: the same transform as a ``tf2_msgs/msg/TFMessage`` (the YAML ``ros2 topic pub``
  takes) and, in its header, the ``static_transform_publisher`` command that keeps it on ``/tf_static``.

Frames are objscan's (docs/conventions.md): ``gripper`` is the TCP, ``camera`` the optical frame (z forward, x
right, y down); ``T_gripper_camera`` maps camera points into the gripper frame, as a URDF origin does.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from common.atomic import atomic_write_bytes
from common.geometry import matrix_to_pose

PARENT, CHILD = "gripper", "camera"
JOINT = "objscan/camera_optical_joint"


def urdf_rpy(R: np.ndarray) -> np.ndarray:
    """URDF's roll, pitch, yaw (fixed axes x, y, z: R = Rz(yaw) Ry(pitch) Rx(roll))."""
    return Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_euler("xyz")


def urdf_joint(T_gripper_camera: np.ndarray, note: str = "") -> str:
    """A fixed URDF joint placing ``camera`` on ``gripper`` (12 significant digits: well below a micrometre)."""
    T = np.asarray(T_gripper_camera, dtype=np.float64)
    xyz = " ".join(f"{v:.12g}" for v in T[:3, 3])
    rpy = " ".join(f"{v:.12g}" for v in urdf_rpy(T[:3, :3]))
    comment = f"  <!-- objscan hand-eye calibration{': ' + note if note else ''}. Replaces the URDF's {JOINT}. -->\n"
    return (f"{comment}  <joint name=\"{JOINT}\" type=\"fixed\">\n"
            f"    <parent link=\"{PARENT}\"/>\n    <child link=\"{CHILD}\"/>\n"
            f"    <origin xyz=\"{xyz}\" rpy=\"{rpy}\"/>\n  </joint>\n")


def tf_static_yaml(T_gripper_camera: np.ndarray, note: str = "") -> str:
    """``tf2_msgs/msg/TFMessage`` YAML of ``gripper -> camera``, with the command that publishes it for good."""
    p, q = matrix_to_pose(np.asarray(T_gripper_camera, dtype=np.float64))
    num = [f"{v:.12g}" for v in (*p, *q)]
    cmd = (f"ros2 run tf2_ros static_transform_publisher --x {num[0]} --y {num[1]} --z {num[2]} "
           f"--qx {num[3]} --qy {num[4]} --qz {num[5]} --qw {num[6]} --frame-id {PARENT} --child-frame-id {CHILD}")
    return (f"# objscan hand-eye calibration{': ' + note if note else ''}\n"
            f"# keep it on /tf_static with:\n#   {cmd}\n"
            "transforms:\n"
            f"- header:\n    frame_id: {PARENT}\n    stamp: {{sec: 0, nanosec: 0}}\n"
            f"  child_frame_id: {CHILD}\n"
            "  transform:\n"
            f"    translation: {{x: {num[0]}, y: {num[1]}, z: {num[2]}}}\n"
            f"    rotation: {{x: {num[3]}, y: {num[4]}, z: {num[5]}, w: {num[6]}}}\n")


def write_ros_files(T_gripper_camera: np.ndarray, calibration_file: str | Path, note: str = "") -> tuple[Path, Path]:
    """Write the URDF joint and the static transform beside ``calibration_file``; their paths."""
    base = Path(calibration_file)
    stem = base.with_suffix("")
    urdf, tf = Path(f"{stem}.urdf.xml"), Path(f"{stem}.tf_static.yaml")
    atomic_write_bytes(urdf, urdf_joint(T_gripper_camera, note).encode())
    atomic_write_bytes(tf, tf_static_yaml(T_gripper_camera, note).encode())
    return urdf, tf
