"""A tiny scan as the orchestrator sees it: the exchanges and stream samples of two views, built in memory.

Real message types with plausible content (a 64x48 frame, small clouds, two grasps, a model), so the
live view is tested on exactly what the tap and the recording carry, without starting a cell.
"""

from __future__ import annotations

import numpy as np

from common import keys
from common.api import GraspPlanReply, GripperRequest, ModelResult, MoveRequest, MoveResult, ViewResult
from common.codec import decode
from common.messages import Grasp, Intrinsics, JointState, Ok, Plane, PointCloud, Pose, RGBDFrame
from services.arm.robot import JOINT_NAMES

R = keys.DEFAULT_ROBOT


def _T(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def _cloud(n: int, seed: int) -> PointCloud:
    rng = np.random.default_rng(seed)
    xyz = (rng.normal(size=(n, 3)) * 0.03 + (0.4, 0.0, 0.05)).astype(np.float32)
    return PointCloud(xyz=xyz, rgb=rng.integers(0, 255, (n, 3), dtype=np.uint8))


def _frame(seq: int) -> RGBDFrame:
    depth = np.full((48, 64), 400 + seq, dtype=np.uint16)
    color = np.zeros((48, 64, 3), dtype=np.uint8)
    color[..., 0] = 200
    return RGBDFrame(color=color, depth=depth, intrinsics=Intrinsics(width=64, height=48, fx=60, fy=60, cx=32, cy=24),
                     T_base_camera=_T(0.3, 0.0, 0.4 + 0.01 * seq), stamp=100.0 + seq, seq=seq)


def scan_items() -> list[tuple[str, float, object, object, object]]:
    """``("exchange", t, key, request, reply)`` and ``("sample", t, None, None, msg)`` in time order."""
    q = np.array([0.1, -0.3, 0.5, 0.0, 0.4, 0.0])
    table = Plane(normal=np.array([0.0, 0.0, 1.0]), offset=0.0, center=np.array([0.4, 0.0, 0.0]))
    grasp_pose = _T(0.4, 0.0, 0.06)
    grasps = [Grasp(contacts=np.zeros((2, 3)), width=0.05, rank=1.0 - 0.1 * i, kind="frontal",
                    poses={"grasp": Pose.from_matrix(_T(0.4, 0.01 * i, 0.06))}) for i in range(2)]
    t = 100.0
    items: list[tuple[str, float, object, object, object]] = []
    for view in range(2):
        items.append(("sample", t, None, None, JointState(names=list(JOINT_NAMES), position=q + 0.1 * view,
                                                           stamp=t)))
        items.append(("sample", t + 0.01, None, None, Ok(info={"state": "scan", "view": view, "views": 2,
                                                                "views_done": view, "status": "running",
                                                                "turns_deg": [0.0, 30.0][: view + 1]})))
        items.append(("exchange", t + 0.5, keys.arm(R, "move"), MoveRequest(kind="joints", q=q),
                      MoveResult(q=q + 0.1 * view, T_base_gripper=_T(0.3, 0, 0.3), T_base_camera=_T(0.3, 0, 0.4))))
        items.append(("exchange", t + 1.0, keys.camera_capture(R), None, _frame(view)))
        items.append(("exchange", t + 2.0, keys.REGISTRATION_STATIC, None,
                      ViewResult(view=view, cloud=_cloud(200, view), table=table, center=np.array([0.4, 0, 0.05]),
                                 height=0.1, scan_poses=np.stack([np.eye(4)] * 3))))
        items.append(("exchange", t + 3.0, keys.GRASP_PLAN, None, GraspPlanReply(grasps=grasps)))
        items.append(("exchange", t + 4.0, keys.arm(R, "move"),
                      MoveRequest(kind="linear", target=grasp_pose, frame="gripper"),
                      MoveResult(q=q, T_base_gripper=grasp_pose, T_base_camera=_T(0.3, 0, 0.4))))
        items.append(("exchange", t + 5.0, keys.arm(R, "gripper"), GripperRequest(opening=0.0), Ok()))
        t += 10.0
    items.append(("exchange", t, keys.REGISTRATION_DYNAMIC, None, ModelResult(cloud=_cloud(500, 9))))
    items.append(("sample", t + 0.1, None, None, Ok(info={"state": "done", "view": 1, "views": 2, "views_done": 2,
                                                          "status": "done"})))
    return items


def over_the_wire(items):  # noqa: ANN001, ANN201
    """The same items after encode/decode, as the tap and the recording deliver them: arrays then point into
    the msgpack buffer, unaligned (Rerun's Arrow import aborts the process on those unless they are copied)."""
    def rt(m):  # noqa: ANN001, ANN202
        return None if m is None else decode(m.encode())
    return [(kind, t, key, rt(req), rt(msg)) for kind, t, key, req, msg in items]


def feed(view, items) -> None:  # noqa: ANN001 - a LiveView
    for kind, t, key, request, msg in items:
        if kind == "exchange":
            view.exchange(t, key, request, msg)
        else:
            view.sample(t, msg)
