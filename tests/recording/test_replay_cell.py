"""RecordedReplies: the replay cell's answer logic (order, tolerance, recorded failures, divergence)."""

from __future__ import annotations

import numpy as np
import pytest

from common.api import GripperRequest, GripperResult, MoveRequest, MoveResult
from common.errors import ObjscanError
from common.messages import Error
from services.recording.errors import ReplayDiverged, ReplayExhausted
from services.recording.reader import Exchange
from services.recording.replay_cell import RecordedReplies, request_difference

MOVE = "objscan/robot0/arm/move"
GRIP = "objscan/robot0/arm/gripper"


def _T(x: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = [x, 0.1, 0.2]
    return T


def _ex(key: str, req, rep, i: int) -> Exchange:  # noqa: ANN001
    return Exchange(key=key, sequence=i, request=req.encode() if req is not None else b"", reply=rep.encode(),
                    t_sent=float(i), t_received=float(i) + 0.1)


def _moved(x: float) -> MoveResult:
    return MoveResult(q=np.full(6, x), T_base_gripper=_T(x), T_base_camera=_T(x + 0.05))


def _recording() -> list[Exchange]:
    return [
        _ex(MOVE, MoveRequest(kind="pose", target=_T(0.30)), _moved(0.30), 1),
        _ex(GRIP, GripperRequest(opening=0.0, force=30.0), GripperResult(opening=0.031, holding=True), 2),
        _ex(MOVE, MoveRequest(kind="linear", target=_T(0.40)), Error(code="line_unreachable", message="no line"), 3),
        _ex(MOVE, MoveRequest(kind="pose", target=_T(0.40)), _moved(0.40), 4),
        _ex(MOVE, MoveRequest(kind="home"), Error(code="unavailable", message="x", detail={"local": True}), 5),
    ]


def test_replies_follow_the_recording_in_order_per_key_with_recorded_failures():
    r = RecordedReplies(_recording())
    first = r.answer(MOVE, MoveRequest(kind="pose", target=_T(0.30)))
    assert isinstance(first, MoveResult) and first.q[0] == 0.30
    assert r.answer(GRIP, GripperRequest(opening=0.0, force=30.0)).holding is True
    with pytest.raises(ObjscanError) as refused:  # the arm refused this line in the recording: so it does now
        r.answer(MOVE, MoveRequest(kind="linear", target=_T(0.40)))
    assert refused.value.code == "line_unreachable"
    assert r.answer(MOVE, MoveRequest(kind="pose", target=_T(0.40))).q[0] == 0.40
    # the "nobody answered" entry was a client-side retry, not a reply: it is skipped
    with pytest.raises(ReplayExhausted):
        r.answer(MOVE, MoveRequest(kind="home"))
    assert r.served == 4 and r.diverged is None


def test_a_request_within_tolerance_is_served_and_its_deviation_reported():
    r = RecordedReplies(_recording(), atol=1e-4)
    r.answer(MOVE, MoveRequest(kind="pose", target=_T(0.30 + 5e-5)))
    assert r.max_deviation == pytest.approx(5e-5, rel=1e-6)


def test_a_differing_request_is_refused_and_the_refusal_latches():
    r = RecordedReplies(_recording(), atol=1e-4)
    with pytest.raises(ReplayDiverged) as div:
        r.answer(MOVE, MoveRequest(kind="pose", target=_T(0.302)))  # 2 mm away from the recorded target
    assert div.value.code == "replay_diverged"
    assert r.diverged["key"] == MOVE and r.diverged["index"] == 0
    assert any("target" in d for d in r.diverged["differences"])
    with pytest.raises(ReplayDiverged):  # even a request that matches the recording is refused now
        r.answer(GRIP, GripperRequest(opening=0.0, force=30.0))


def test_request_difference_compares_types_strings_flags_and_numbers():
    a = MoveRequest(kind="pose", target=_T(0.3), dry_run=False)
    assert request_difference(a, MoveRequest(kind="pose", target=_T(0.3))) == ([], 0.0)
    assert request_difference(a, MoveRequest(kind="pose", target=_T(0.3), dry_run=True))[0]
    assert request_difference(a, MoveRequest(kind="linear", target=_T(0.3)))[0]
    assert request_difference(a, GripperRequest(opening=0.0))[0]
    assert request_difference(None, None) == ([], 0.0)
    assert request_difference(a, None)[0]
    diffs, worst = request_difference(GripperRequest(opening=0.02), GripperRequest(opening=0.021), atol=1e-4)
    assert diffs and worst == pytest.approx(0.001)
