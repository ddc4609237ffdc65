"""The orchestrator's ``Cell`` on a scripted network: which failures it waits out and sends again (a service
gone, or one behind it gone, e.g. the camera's twin restarting), which it hands to the machine at once, and
the twin's world key, where silence means "no twin in this cell" until a twin has answered once."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from common.api import GripperResult
from common.errors import RemoteError, ServiceUnavailable
from common.messages import Intrinsics, Ok, RGBDFrame
from services.orchestrator.cell import Cell

pytestmark = pytest.mark.timeout(60)


class Script:
    """A requester that fails the first calls of each key as told, then answers."""

    def __init__(self, failures: dict[str, list[Exception]], answers: dict[str, object]):
        self.failures = {k: list(v) for k, v in failures.items()}
        self.answers = answers
        self.calls: list[str] = []

    async def __call__(self, key: str, msg, *, timeout: float):  # noqa: ANN001, ANN204
        self.calls.append(key)
        op = key.rsplit("/", 1)[-1]
        pending = self.failures.get(op) or []
        if pending:
            raise pending.pop(0)
        return self.answers[op]


def _frame() -> RGBDFrame:
    K = Intrinsics(width=4, height=2, fx=1.0, fy=1.0, cx=2.0, cy=1.0)
    return RGBDFrame(color=np.zeros((2, 4, 3), np.uint8), depth=np.zeros((2, 4), np.uint16), depth_scale=0.001,
                     intrinsics=K, T_base_camera=np.eye(4))


def test_capture_waits_while_the_camera_says_its_twin_is_unavailable():
    script = Script({"capture": [RemoteError("no twin", code="unavailable"), RemoteError("slow", code="timeout"),
                                 ServiceUnavailable("camera gone")]}, {"capture": _frame()})
    cell = Cell(script, "r0", retry_window_s=30)
    frame = asyncio.run(cell.capture(4, 2))
    assert isinstance(frame, RGBDFrame) and cell.retries == 3 and len(script.calls) == 4


def test_a_real_refusal_is_not_sent_again():
    script = Script({"capture": [RemoteError("bad size", code="invalid_request")]}, {"capture": _frame()})
    cell = Cell(script, "r0", retry_window_s=30)
    with pytest.raises(RemoteError) as err:
        asyncio.run(cell.capture(4, 2))
    assert err.value.code == "invalid_request" and cell.retries == 0 and len(script.calls) == 1


def test_retries_end_with_the_window():
    script = Script({"capture": [RemoteError("no twin", code="unavailable")] * 100}, {"capture": _frame()})
    cell = Cell(script, "r0", retry_window_s=1.0)
    with pytest.raises(RemoteError):
        asyncio.run(cell.capture(4, 2))
    assert 1 <= cell.retries <= 3  # backoff 0.5 s, 1 s: bounded, not a tight loop


def test_sim_world_silence_means_no_twin_until_a_twin_answered_then_a_restart():
    cell = Cell(Script({"world": [ServiceUnavailable("none")]}, {"world": Ok(info={})}), "r0", retry_window_s=30)
    with pytest.raises(ServiceUnavailable):  # session start on a real cell: no twin, told at once
        asyncio.run(cell.sim("reset"))
    assert cell.retries == 0 and not cell.twin_seen

    script = Script({}, {"world": Ok(info={"armed": True})})
    cell = Cell(script, "r0", retry_window_s=30)
    asyncio.run(cell.sim("reset"))
    assert cell.twin_seen
    script.failures["world"] = [ServiceUnavailable("twin restarting")]
    assert asyncio.run(cell.sim("gt_points")) == {"armed": True}  # waited for the restarted twin
    assert cell.retries == 1


def test_a_busy_arm_is_waited_for_a_resumed_orchestrator_finds_the_old_motion_running():
    done = GripperResult(opening=0.1, holding=False)
    script = Script({"gripper": [RemoteError("another motion is running", code="busy")] * 2}, {"gripper": done})
    cell = Cell(script, "r0", retry_window_s=30)
    assert asyncio.run(cell.gripper(0.1)) is done
    assert cell.retries == 2 and len(script.calls) == 3
