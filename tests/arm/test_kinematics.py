"""FK against an independent URDF chain, IK round trips and refusals, frames and hand-eye."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from common.geometry import transform_error
from services.arm.errors import BadCommand, IKError
from services.arm.kinematics import Kinematics, KinematicsConfig, wrist_flip
from services.arm.robot import URDF_PATH
from tests.arm.conftest import Q_HOME, random_reachable_q


# ---------------------------------------------------------------- independent URDF chain (numpy only)
def _origin(el: ET.Element | None) -> np.ndarray:
    T = np.eye(4)
    if el is None:
        return T
    xyz = np.array([float(v) for v in el.get("xyz", "0 0 0").split()])
    r, p, y = (float(v) for v in el.get("rpy", "0 0 0").split())
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    T[:3, :3] = Rz @ Ry @ Rx  # URDF: fixed-axis roll, pitch, yaw
    T[:3, 3] = xyz
    return T


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    return T


def urdf_chain_fk(q: np.ndarray, link: str) -> np.ndarray:
    """T_link1_link by walking the URDF XML from ``link`` up to robot1/link1 (arm joints from ``q``)."""
    root = ET.parse(URDF_PATH).getroot()
    by_child = {j.find("child").get("link"): j for j in root.findall("joint")}
    values = {f"robot1/joint{i + 1}": q[i] for i in range(6)}
    T = np.eye(4)
    while link != "robot1/link1":
        j = by_child[link]
        step = _origin(j.find("origin"))
        if j.get("type") == "revolute":
            axis = np.array([float(v) for v in j.find("axis").get("xyz").split()])
            step = step @ _axis_rotation(axis, values.get(j.get("name"), 0.0))
        T = step @ T
        link = j.find("parent").get("link")
    return T


@pytest.mark.parametrize("frame,link", [("flange", "robot1/end_link"), ("gripper", "gripper"), ("camera", "camera")])
def test_fk_matches_independent_urdf_chain(kin, rng, frame, link):
    configs = [np.zeros(6), Q_HOME, *[rng.uniform(kin.lower, kin.upper) for _ in range(8)]]
    for q in configs:
        np.testing.assert_allclose(kin.fk(q, frame), urdf_chain_fk(q, link), atol=1e-9)


def test_frames_follow_the_conventions(kin):
    # at q = 0 the PAPRAS arm stretches along +x: the gripper approaches along base x with z up
    T = kin.fk(np.zeros(6), "gripper")
    np.testing.assert_allclose(T[:3, :3], np.eye(3), atol=1e-9)
    assert T[2, 3] > 0.4  # well above the table
    C = kin.fk(np.zeros(6), "camera")
    np.testing.assert_allclose(C[:3, 2], [1, 0, 0], atol=1e-9)  # optical z looks along the approach
    np.testing.assert_allclose(C[:3, 1], [0, 0, -1], atol=1e-9)  # image y points down
    assert C[2, 3] > T[2, 3]  # the camera sits on top of the gripper


def test_tcp_lies_between_the_closed_finger_pads(kin):
    """The TCP is the point between the pads when the RH-P12-RN is closed (the paper's grasp centre)."""
    import pinocchio as pin

    m, d = kin.full_model, kin.full_data
    pin.framesForwardKinematics(m, d, kin.full_q(Q_HOME, finger_angle=1.1))
    pad_r = d.oMf[m.getFrameId("robot1/gripper_link_r2")].act(np.array([0.0, -0.0039, 0.02]))
    pad_l = d.oMf[m.getFrameId("robot1/gripper_link_l2")].act(np.array([0.0, 0.0039, 0.02]))
    tcp = kin.fk(Q_HOME, "gripper")
    assert np.linalg.norm((pad_r + pad_l) / 2 - tcp[:3, 3]) < 1.5e-3
    across = (pad_r - pad_l) / max(np.linalg.norm(pad_r - pad_l), 1e-9)
    # open fingers: the pads sit on the gripper y-axis, 106 mm apart
    pin.framesForwardKinematics(m, d, kin.full_q(Q_HOME, finger_angle=0.0))
    pad_r = d.oMf[m.getFrameId("robot1/gripper_link_r2")].act(np.array([0.0, -0.0039, 0.02]))
    pad_l = d.oMf[m.getFrameId("robot1/gripper_link_l2")].act(np.array([0.0, 0.0039, 0.02]))
    across = (pad_l - pad_r) / np.linalg.norm(pad_l - pad_r)
    assert abs(across @ tcp[:3, 1]) > 0.999
    assert 0.104 < kin.max_opening < 0.110
    assert kin.opening(kin.finger_angle(0.05)) == pytest.approx(0.05, abs=1e-4)


def test_jacobian_matches_finite_differences(kin, rng):
    q = rng.uniform(kin.lower, kin.upper) * 0.5
    J = kin.jacobian(q, "gripper", "local_world_aligned")
    h = 1e-6
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = h
        dp = (kin.fk(q + dq)[:3, 3] - kin.fk(q - dq)[:3, 3]) / (2 * h)
        np.testing.assert_allclose(J[:3, i], dp, atol=1e-6)


def test_ik_round_trips_warm_start(kin, rng):
    for q in random_reachable_q(kin, rng, 60):
        T = kin.fk(q)
        sol = kin.ik(T, q + rng.normal(0.0, 0.15, 6))
        dt, dr = transform_error(kin.fk(sol.q), T)
        assert dt < 1e-4 and dr < 0.1
        assert kin.within_limits(sol.q)


def test_ik_round_trips_cold_start(kin, rng):
    ok = 0
    qs = random_reachable_q(kin, rng, 40)
    for q in qs:
        T = kin.fk(q)
        try:
            sol = kin.ik(T)
        except IKError as e:
            assert e.code in {"joint_limits", "unreachable", "singular"}
            continue
        dt, dr = transform_error(sol.T_achieved, T)
        assert dt < 1e-4 and dr < 0.1
        np.testing.assert_allclose(sol.T_achieved, kin.fk(sol.q), atol=1e-12)
        ok += 1
    assert ok >= 0.9 * len(qs)


def test_ik_refuses_unreachable_with_a_reason(kin):
    far = np.eye(4)
    far[:3, 3] = [1.5, 0.0, 0.3]  # the arm reaches ~0.75 m
    with pytest.raises(IKError) as e:
        kin.ik(far)
    assert e.value.code == "unreachable"
    # horizontal frontal grasp low and close to the base: needs joint 5 beyond its +-90 deg
    low = np.eye(4)
    low[:3, 3] = [0.36, 0.0, 0.10]
    with pytest.raises(IKError) as e:
        kin.ik(low)
    assert e.value.code == "joint_limits"
    assert e.value.detail["joints_out_of_limits"]


def test_free_roll_turns_about_the_approach_axis(kin):
    q = np.array([0.2, 0.3, -1.0, 0.2, 0.8, 0.1])
    T = kin.fk(q)
    # exactly reachable: free roll keeps roll ~ 0
    sol = kin.ik(T, q + 0.1, free_roll=True)
    assert abs(sol.roll) < np.radians(0.05)
    # ask for a rolled version: the solution keeps position and approach axis, and reports the roll used
    R = Rotation.from_euler("x", 70, degrees=True).as_matrix()
    T2 = T.copy()
    T2[:3, :3] = T[:3, :3] @ R
    sol = kin.ik(T2, q, free_roll=True)
    A = kin.fk(sol.q)
    assert np.linalg.norm(A[:3, 3] - T2[:3, 3]) < 1e-4
    assert np.degrees(np.arccos(np.clip(A[:3, 0] @ T2[:3, 0], -1, 1))) < 0.1
    expected = T2.copy()
    expected[:3, :3] = T2[:3, :3] @ Rotation.from_euler("x", sol.roll).as_matrix()
    dt, dr = transform_error(A, expected)
    assert dt < 1e-4 and dr < 0.1


def test_hand_eye_is_configurable(kin):
    T_gc = np.eye(4)
    T_gc[:3, :3] = Rotation.from_euler("xyz", [5, -3, 2], degrees=True).as_matrix()
    T_gc[:3, 3] = [0.01, 0.03, 0.05]
    k2 = Kinematics(KinematicsConfig(T_gripper_camera=T_gc))
    np.testing.assert_allclose(k2.fk(Q_HOME, "camera"), k2.fk(Q_HOME, "gripper") @ T_gc, atol=1e-12)
    np.testing.assert_allclose(k2.T_gripper_camera, T_gc, atol=1e-12)
    # the default is the URDF mount
    np.testing.assert_allclose(kin.fk(Q_HOME, "camera"), kin.fk(Q_HOME, "gripper") @ kin.T_gripper_camera, atol=1e-12)


@pytest.mark.parametrize(
    "bad",
    [np.full((4, 4), np.nan), np.eye(3), np.diag([2.0, 1.0, 1.0, 1.0]), np.diag([-1.0, 1.0, 1.0, 1.0])],
)
def test_malformed_targets_are_refused(kin, bad):
    with pytest.raises(BadCommand):
        kin.ik(bad)


def test_malformed_joints_and_frames_are_refused(kin):
    with pytest.raises(BadCommand):
        kin.fk(np.zeros(5))
    with pytest.raises(BadCommand):
        kin.fk(np.array([0, 0, np.nan, 0, 0, 0]))
    with pytest.raises(BadCommand) as e:
        kin.fk(np.zeros(6), "nose")
    assert e.value.code == "unknown_frame"


# ---------------------------------------------------------------- IK branch choice
def test_wrist_flip_is_the_same_pose(kin, rng):
    for q in random_reachable_q(kin, rng, 10):
        q = q.copy()
        q[3] = np.clip(q[3], -1.5, 1.5)
        np.testing.assert_allclose(kin.fk(wrist_flip(q)), kin.fk(q), atol=1e-12)
        np.testing.assert_allclose(wrist_flip(wrist_flip(q)), q, atol=1e-12)


def test_ik_takes_the_nearest_branch_not_the_first_one_found(kin):
    """Measured in an acquisition: from a scan posture, the DLS run seeded with the current joints converged on
    the far wrist branch (joint 6 at -2.2 rad, 0.9 rad from its limit, which the turn then ran into) and was
    taken at once, although the other wrist branch is 1.5 rad closer."""
    q_scan = np.array([0.597, -0.21, 0.198, -0.69, 1.176, 1.119])
    q_far = np.array([-0.563, 0.429, 0.163, 1.819, 1.221, -2.208])
    sol = kin.ik(kin.fk(q_far), q_scan)
    np.testing.assert_allclose(sol.T_achieved, kin.fk(q_far), atol=1e-5)
    np.testing.assert_allclose(sol.q, wrist_flip(q_far), atol=1e-3)
    assert np.linalg.norm(sol.q - q_scan) < np.linalg.norm(q_far - q_scan) - 1.0


def test_ik_from_a_nearby_configuration_stays_on_its_branch(kin, rng):
    for q in random_reachable_q(kin, rng, 10):
        q_near = np.clip(q + rng.normal(0.0, 0.05, 6), kin.lower, kin.upper)
        sol = kin.ik(kin.fk(q), q_near)
        assert np.max(np.abs(sol.q - q)) < 0.05 + 1e-3
