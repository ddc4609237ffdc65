"""The state machine notices a toppled object (its height changed between views) and restarts the views
from where it lies instead of registering the new resting pose as the next 30-degree turn."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from common.api import ViewResult
from common.messages import Intrinsics, Plane, PointCloud, RGBDFrame
from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.machine import Acquisition, AcquisitionFailed, State
from services.orchestrator.topple import topple_reason
from services.session_store import SessionStore


class RegisterOnlyCell:
    """Answers static registration with a view of the given object height (nothing else is called)."""

    def __init__(self, height: float):
        self.height = height

    async def register_static(self, frames, view, profile, pose_accuracy=None):  # noqa: ANN001
        xyz = np.random.default_rng(0).uniform(-0.03, 0.03, (500, 3)).astype(np.float32)
        return ViewResult(view=view, cloud=PointCloud(xyz=xyz, normals=np.tile([0, 0, 1], (500, 1)).astype(np.float32)),
                          table=Plane(normal=np.array([0.0, 0.0, 1.0]), offset=0.0, center=np.zeros(3)),
                          center=np.array([0.6, 0.0, 0.0]), height=self.height, scan_poses=np.zeros((0, 4, 4)))


def _frame() -> RGBDFrame:
    return RGBDFrame(color=np.zeros((4, 4, 3), np.uint8), depth=np.zeros((4, 4), np.uint16),
                     intrinsics=Intrinsics(width=4, height=4, fx=3.0, fy=3.0, cx=2.0, cy=2.0), T_base_camera=np.eye(4))


def _at_view_2(tmp_path, height: float, restarts: int = 0) -> Acquisition:
    store = SessionStore(tmp_path)
    for v in range(3):
        for j in range(3):
            store.save_scan(v, j, _frame())
    acq = Acquisition(RegisterOnlyCell(height), store, AcquisitionConfig(views=12))  # type: ignore[arg-type]
    acq.j.update(view=2, state="register", turns_deg=[0.0, 30.0, 60.0], heights={"-1": 0.20, "0": 0.20, "1": 0.20},
                 centers={"-1": [0.6, 0, 0], "0": [0.6, 0, 0], "1": [0.6, 0, 0]}, turn_direction=1,
                 topple_restarts=restarts)
    return acq


def test_a_view_standing_as_before_is_registered(tmp_path):
    acq = _at_view_2(tmp_path, 0.195)
    assert asyncio.run(acq.register()) == State.PLAN_GRASP
    assert acq.view == 2 and acq.store.has_view(2)


def test_a_toppled_object_restarts_the_views_from_where_it_lies(tmp_path):
    acq = _at_view_2(tmp_path, 0.07)  # a 200 mm tall box now lies on its 70 mm side
    assert asyncio.run(acq.register()) == State.SCAN
    assert acq.view == 0 and acq.j.turns_deg == [0.0] and acq.j.turn_direction is None
    assert acq.j.heights == {"-1": 0.07}
    assert not (tmp_path / "view_02").exists() and not acq.store.has_view(2)
    assert (tmp_path / "view_00_toppled1").is_dir() and (tmp_path / "view_02_toppled1").is_dir()
    assert any(d["what"].startswith("object toppled") for d in acq.j.decisions)


def test_toppling_again_after_a_restart_ends_with_the_reason(tmp_path):
    acq = _at_view_2(tmp_path, 0.07, restarts=1)
    with pytest.raises(AcquisitionFailed) as e:
        asyncio.run(acq.register())
    assert "toppled" in e.value.message and "200 mm to 70 mm" in e.value.message


def test_the_height_tolerance():
    assert topple_reason(0.20, 0.185, 0.02, 0.25, 3) is None
    assert topple_reason(0.05, 0.065, 0.02, 0.25, 3) is None
    assert topple_reason(0.05, 0.10, 0.02, 0.25, 3) is not None  # stood up on an end
    assert topple_reason(None, 0.10, 0.02, 0.25, 0) is None
