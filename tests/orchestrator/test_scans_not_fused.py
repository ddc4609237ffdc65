"""A view whose static registration left a scan out (failed its check, or a correction beyond the arm's
accuracy) is taken again through the re-scan path, a bounded number of times, then kept without that scan;
the arm's pose accuracy goes with every static request."""

from __future__ import annotations

import asyncio

import numpy as np

from common.api import ViewResult
from common.messages import Intrinsics, Plane, PointCloud, RGBDFrame
from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.machine import Acquisition, State
from services.session_store import SessionStore

LEFT_OUT = [{"index": 2, "reason": "implausible: 412.0 mm / 78.38 deg from the arm's pose, beyond the 34.0 mm / "
                                    "7.07 deg its accuracy allows"}]


class LeavesScan2OutCell:
    """Static registration that always leaves scan 2 out; records the pose accuracy of each request."""

    def __init__(self) -> None:
        self.accuracies: list[dict | None] = []

    async def register_static(self, frames, view, profile, pose_accuracy=None):  # noqa: ANN001
        self.accuracies.append(pose_accuracy)
        xyz = np.random.default_rng(0).uniform(-0.03, 0.03, (500, 3)).astype(np.float32)
        return ViewResult(view=view, cloud=PointCloud(xyz=xyz, normals=np.tile([0, 0, 1], (500, 1)).astype(np.float32)),
                          table=Plane(normal=np.array([0.0, 0.0, 1.0]), offset=0.0, center=np.zeros(3)),
                          center=np.array([0.6, 0.0, 0.0]), height=0.2, scan_poses=np.zeros((0, 4, 4)),
                          figures={"scans_left_out": LEFT_OUT})


def _frame() -> RGBDFrame:
    return RGBDFrame(color=np.zeros((4, 4, 3), np.uint8), depth=np.zeros((4, 4), np.uint16),
                     intrinsics=Intrinsics(width=4, height=4, fx=3.0, fy=3.0, cx=2.0, cy=2.0), T_base_camera=np.eye(4))


def _at_view_1(tmp_path, max_rescans: int) -> Acquisition:
    store = SessionStore(tmp_path)
    for v in range(2):
        for j in range(3):
            store.save_scan(v, j, _frame())
    config = AcquisitionConfig(views=12, max_rescans=max_rescans,
                               pose_accuracy={"position_sigma_mm": 3.0, "orientation_sigma_deg": 1.0})
    acq = Acquisition(LeavesScan2OutCell(), store, config)  # type: ignore[arg-type]
    acq.j.update(view=1, state="register", turns_deg=[0.0, 30.0], heights={"-1": 0.2, "0": 0.2},
                 centers={"-1": [0.6, 0, 0], "0": [0.6, 0, 0]}, turn_direction=1)
    return acq


def test_a_view_with_a_scan_left_out_is_taken_again(tmp_path):
    acq = _at_view_1(tmp_path, max_rescans=2)
    assert asyncio.run(acq.register()) == State.SCAN
    assert acq.cell.accuracies == [{"position_sigma_mm": 3.0, "orientation_sigma_deg": 1.0}]
    assert acq.j.rescans == {"1": 1} and not acq.store.has_view(1)
    assert (tmp_path / "view_01_attempt1").is_dir()  # the old frames are kept, moved aside
    decision = next(d for d in acq.j.decisions if d["what"].startswith("scans not fused"))
    assert "scan 2 (implausible" in next(d for d in acq.j.decisions if d["what"] == "re-scan")["reason"]
    assert decision["left_out"] == LEFT_OUT


def test_once_the_re_scans_are_used_up_the_view_is_kept_without_the_scan(tmp_path):
    acq = _at_view_1(tmp_path, max_rescans=1)
    acq.j.rescans = {"1": 1}
    assert asyncio.run(acq.register()) == State.PLAN_GRASP
    assert acq.store.has_view(1)
    assert any(d["what"].startswith("view kept without the scans") for d in acq.j.decisions)
