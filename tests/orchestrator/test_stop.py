"""The orchestrator's stop comes first: with the arm unavailable, ``orchestrator/stop`` parks the acquisition
in ``stopped`` at once and answers with what the arm said (here: nothing), instead of holding the stop in
the retry loop every other arm call goes through (up to two minutes, the acquisition running all along)."""

from __future__ import annotations

import asyncio
import threading
import time

from common import keys
from common.client import request_sync
from common.codec import decode
from common.errors import RemoteError, ServiceUnavailable
from common.launcher import ProcessSpec
from common.messages import Ok, Request
from services.orchestrator.cell import Cell

ROBOT = keys.DEFAULT_ROBOT


def test_stop_with_an_unavailable_arm_stops_the_acquisition_at_once(service_group, tmp_path):
    group = service_group
    group.launch([ProcessSpec("services.orchestrator", ["--sessions", str(tmp_path)], service="orchestrator")])
    stopped_at: list[float] = []
    seen = threading.Event()

    def on_status(sample) -> None:  # noqa: ANN001
        msg = decode(sample.payload.to_bytes())
        if isinstance(msg, Ok) and msg.info.get("status") == "stopped" and not stopped_at:
            stopped_at.append(time.monotonic())
            seen.set()

    sub = group.session.declare_subscriber(keys.orchestrator(ROBOT, "status"), on_status)
    try:
        params = {"out": str(tmp_path / "s"), "record": False, "library": None,
                  "config": {"object": "milk", "views": 2}}
        request_sync(group.session, keys.orchestrator(ROBOT, "run"), Request(params=params), timeout=30)
        deadline = time.monotonic() + 30  # no arm, no twin: the run waits for the arm (retrying)
        while time.monotonic() < deadline:
            s = request_sync(group.session, keys.orchestrator(ROBOT, "status"), timeout=10).info
            if s.get("status") == "running":
                break
            time.sleep(0.2)
        assert s.get("status") == "running", s
        time.sleep(1.5)  # well inside the arm retry loop
        t0 = time.monotonic()
        reply = request_sync(group.session, keys.orchestrator(ROBOT, "stop"), timeout=10)
        answered_s = time.monotonic() - t0
        assert isinstance(reply, Ok) and reply.info["stopped"] is True
        assert seen.wait(5.0), "the acquisition never published 'stopped'"
        assert stopped_at[0] - t0 <= 1.0, f"acquisition stopped {stopped_at[0] - t0:.2f} s after the stop"
        assert answered_s <= 4.0  # one bounded e-stop attempt plus the park, never the retry window
        arm = reply.info["arm"]
        assert arm["answered"] is False and arm["code"] in ("unavailable", "timeout"), arm
        final = request_sync(group.session, keys.orchestrator(ROBOT, "status"), timeout=10).info
        assert final["status"] == "stopped" and final["state"] == "stopped", final
    finally:
        sub.undeclare()


class OneAnswer:
    """A requester that answers (or raises) the same thing every time and counts the sends."""

    def __init__(self, answer: object):
        self.answer, self.sent = answer, 0

    async def __call__(self, key: str, msg, *, timeout: float):  # noqa: ANN001, ANN204
        self.sent += 1
        if isinstance(self.answer, Exception):
            raise self.answer
        return self.answer


def test_the_stop_e_stop_is_sent_once_and_reports_the_arm_answer_or_its_absence():
    gone = OneAnswer(ServiceUnavailable("no service answers"))
    t0 = time.monotonic()
    out = asyncio.run(Cell(gone, ROBOT).estop_once(timeout=0.5))
    assert gone.sent == 1 and time.monotonic() - t0 < 0.5  # no retry, no back-off sleep
    assert out["answered"] is False and out["code"] == "unavailable" and "estopped" not in out
    ok = OneAnswer(Ok(info={"estopped": True}))
    out = asyncio.run(Cell(ok, ROBOT).estop_once())
    assert out["answered"] is True and out["estopped"] is True and out["ms"] >= 0
    refused = OneAnswer(RemoteError("hold not written to joint3", code="estop_failed"))
    out = asyncio.run(Cell(refused, ROBOT).estop_once())
    assert out == {**out, "answered": True, "estopped": False, "code": "estop_failed"} and refused.sent == 1
