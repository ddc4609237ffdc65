"""The acquisition plans its scan poses from the object's *estimated* centre: the locate
frame's static registration for view 0, the latest registered view after; never from where the object was
expected (the workspace centre) when the estimate says otherwise."""

from __future__ import annotations

import asyncio

import numpy as np

from common.api import ViewResult
from common.messages import Intrinsics, Plane, PointCloud, RGBDFrame
from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.machine import Acquisition, State
from services.session_store import SessionStore

ESTIMATE = np.array([0.622, 0.024, 0.0])  # ~3 cm off the expected spot, as the realistic twin puts it
HEIGHT = 0.16


class EstimatingCell:
    """Locates the object at ``ESTIMATE`` and records every move asked for (dry runs included)."""

    def __init__(self) -> None:
        self.moves: list[tuple[str, np.ndarray | None, bool]] = []

    async def move(self, kind, *, target=None, frame="gripper", dry_run=False, **_kw):  # noqa: ANN001, ANN003
        self.moves.append((kind, None if target is None else np.asarray(target), dry_run))

    async def capture(self, width, height):  # noqa: ANN001
        return RGBDFrame(color=np.zeros((4, 4, 3), np.uint8), depth=np.zeros((4, 4), np.uint16),
                         intrinsics=Intrinsics(width=4, height=4, fx=3.0, fy=3.0, cx=2.0, cy=2.0),
                         T_base_camera=np.eye(4))

    async def register_static(self, frames, view, profile, pose_accuracy=None):  # noqa: ANN001
        xyz = np.zeros((10, 3), np.float32)
        return ViewResult(view=view, cloud=PointCloud(xyz=xyz, normals=np.tile([0, 0, 1], (10, 1)).astype(np.float32)),
                          table=Plane(normal=np.array([0.0, 0.0, 1.0]), offset=0.0, center=np.zeros(3)),
                          center=ESTIMATE.copy(), height=HEIGHT, scan_poses=np.zeros((0, 4, 4)))


def _axis_miss(T_cam: np.ndarray, point: np.ndarray) -> float:
    """Distance (m) from ``point`` to the camera's optical axis (+z)."""
    v = point - T_cam[:3, 3]
    z = T_cam[:3, 2]
    return float(np.linalg.norm(v - (v @ z) * z))


def test_view_0_scan_poses_aim_at_the_located_estimate_not_the_expected_spot(tmp_path):
    cell = EstimatingCell()
    acq = Acquisition(cell, SessionStore(tmp_path), AcquisitionConfig(views=12))  # type: ignore[arg-type]
    assert asyncio.run(acq.locate()) == State.SCAN
    np.testing.assert_allclose(acq.j.centers["-1"], ESTIMATE)
    poses = asyncio.run(acq._reachable_scan_set(0))
    assert len(poses) == 3
    aimed = np.array([ESTIMATE[0], ESTIMATE[1], HEIGHT / 2])
    expected_spot = np.array([*acq.config.workspace_center, HEIGHT / 2])
    for T in poses:
        assert _axis_miss(T, aimed) < 1e-6
        assert _axis_miss(T, expected_spot) > 0.01  # the expected spot is not what the poses aim at
    dry = [m for m in cell.moves if m[2]]
    assert len(dry) == 3 and all(np.allclose(t, p) for (_, t, _), p in zip(dry, poses))  # checked as planned


def test_a_later_view_plans_from_the_latest_registered_view(tmp_path):
    acq = Acquisition(EstimatingCell(), SessionStore(tmp_path), AcquisitionConfig(views=12))  # type: ignore[arg-type]
    acq.j.update(centers={"-1": [0.6, 0.0, 0.0], "0": [0.61, 0.01, 0.0], "2": [0.58, -0.02, 0.0]},
                 heights={"-1": 0.10, "0": 0.12, "2": 0.14})
    centre, height = acq._object_estimate(3)
    np.testing.assert_allclose(centre, [0.58, -0.02, 0.0])
    assert height == 0.14
    centre, height = acq._object_estimate(1)  # view 1 not registered yet: view 0's estimate
    np.testing.assert_allclose(centre, [0.61, 0.01, 0.0])
    assert height == 0.12
