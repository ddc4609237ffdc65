"""The live view's joint maths is the arm's: chaining the URDF joints gives pinocchio's poses."""

from __future__ import annotations

import numpy as np

from services.arm.kinematics import Kinematics
from services.live.urdf_joints import joint_transforms, load_joints


def test_chained_joint_transforms_match_pinocchio_forward_kinematics():
    kin = Kinematics()
    joints = load_joints()
    rng = np.random.default_rng(4)
    for _ in range(5):
        q = rng.uniform(-1.5, 1.5, size=6)
        T = {"world": np.eye(4)}
        for j, Tj in joint_transforms(joints, list(kin.joint_names), q, include_fixed=True):
            T[j.child] = T[j.parent] @ Tj
        for frame, link in (("flange", "robot1/end_link"), ("gripper", "gripper"), ("camera", "camera")):
            assert np.abs(T[link] - kin.fk(q, frame)).max() < 1e-9, frame


def test_mimic_fingers_follow_their_driver_and_unknown_joints_stay_at_zero():
    joints = load_joints()
    out = {j.name: T for j, T in joint_transforms(joints, ["robot1/gripper"], np.array([0.5]))}
    r2 = next(j for j in joints if j.name == "robot1/gripper_r2")
    assert np.allclose(out["robot1/gripper_r2"], r2.transform(0.5 / 1.1))
    j3 = next(j for j in joints if j.name == "robot1/joint3")
    assert np.allclose(out["robot1/joint3"], j3.origin)
