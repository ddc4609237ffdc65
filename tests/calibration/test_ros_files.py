"""The hand-eye result as a URDF joint and a static transform: read back as ROS would, they give the calibrated
mount (the URDF's fixed-axis roll-pitch-yaw rebuilt by hand; the YAML's quaternion through numpy alone)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import yaml

from services.calibration.ros_files import write_ros_files


def _rot(axis: int, a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    i, j = (axis + 1) % 3, (axis + 2) % 3  # cyclic: x -> (y, z), y -> (z, x), z -> (x, y)
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _quat_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def test_urdf_joint_and_tf_static_carry_the_calibrated_mount(tmp_path):
    rng = np.random.default_rng(3)
    X = np.eye(4)
    X[:3, :3] = _rot(2, 1.2) @ _rot(1, -0.4) @ _rot(0, 2.9)
    X[:3, 3] = rng.normal(size=3) * 0.05
    urdf, tf = write_ros_files(X, tmp_path / "hand_eye.json", note="test")
    assert (urdf.name, tf.name) == ("hand_eye.urdf.xml", "hand_eye.tf_static.yaml")
    joint = ET.fromstring(urdf.read_text())
    assert joint.get("type") == "fixed" and joint.get("name") == "objscan/camera_optical_joint"
    assert (joint.find("parent").get("link"), joint.find("child").get("link")) == ("gripper", "camera")
    origin = joint.find("origin")
    r, p, y = (float(v) for v in origin.get("rpy").split())
    np.testing.assert_allclose(_rot(2, y) @ _rot(1, p) @ _rot(0, r), X[:3, :3], atol=1e-10)
    np.testing.assert_allclose([float(v) for v in origin.get("xyz").split()], X[:3, 3], atol=1e-12)
    doc = yaml.safe_load(tf.read_text())
    t = doc["transforms"][0]
    assert (t["header"]["frame_id"], t["child_frame_id"]) == ("gripper", "camera")
    q = t["transform"]["rotation"]
    np.testing.assert_allclose(_quat_matrix(q["x"], q["y"], q["z"], q["w"]), X[:3, :3], atol=1e-10)
    tr = t["transform"]["translation"]
    np.testing.assert_allclose([tr["x"], tr["y"], tr["z"]], X[:3, 3], atol=1e-12)
    assert "static_transform_publisher" in tf.read_text()
