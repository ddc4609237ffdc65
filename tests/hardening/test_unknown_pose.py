"""A frame whose camera pose is unknown is refused downstream.

Why: a real camera whose pose query failed stamped the identity (``pose_source=unknown``) and the
orchestrator stored it as a scan and registration placed it at the base origin. Now the orchestrator's
``Cell`` captures again and then refuses with ``no_camera_pose``, and static registration refuses such a
frame (from the wire or read back from a session folder)."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from common.errors import ObjscanError
from common.messages import Intrinsics, RGBDFrame
from common.session_folder import read_scan, write_scan
from services.orchestrator.cell import POSE_ATTEMPTS, Cell
from services.registration.cloud import check_frame, frame_to_cloud


def _frame(pose_source: str) -> RGBDFrame:
    depth = np.full((48, 64), 500, np.uint16)
    return RGBDFrame(color=np.zeros((48, 64, 3), np.uint8), depth=depth, T_base_camera=np.eye(4),
                     intrinsics=Intrinsics(width=64, height=48, fx=60.0, fy=60.0, cx=32.0, cy=24.0),
                     meta={"pose_source": pose_source})


def test_registration_refuses_a_frame_without_a_pose(tmp_path):
    check_frame(_frame("given"))
    with pytest.raises(ObjscanError) as err:
        check_frame(_frame("unknown"))
    assert err.value.code == "no_camera_pose"
    write_scan(tmp_path, 0, 0, _frame("unknown"))  # a frame stored before the fix, read back
    with pytest.raises(ObjscanError) as err:
        frame_to_cloud(read_scan(tmp_path, 0, 0))
    assert err.value.code == "no_camera_pose"


def test_the_cell_captures_again_then_refuses():
    answers = [_frame("unknown"), _frame("given")]
    sent: list[str] = []

    async def camera(key, msg=None, **kw):  # noqa: ANN001, ANN003, ANN202
        sent.append(key)
        return answers.pop(0) if answers else _frame("unknown")

    frame = asyncio.run(Cell(camera, "robot0").capture(64, 48))
    assert frame.meta["pose_source"] == "given" and len(sent) == 2
    sent.clear()
    with pytest.raises(ObjscanError) as err:
        asyncio.run(Cell(camera, "robot0").capture(64, 48))
    assert err.value.code == "no_camera_pose" and len(sent) == POSE_ATTEMPTS
