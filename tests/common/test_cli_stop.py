"""Ctrl-C during ``objscan scan``: the line printed is the orchestrator's real answer (the arm's e-stop
confirmed, refused, or not answered within a stated wait), never a claim made before anything came back,
and every Ctrl-C sends the stop again."""

from __future__ import annotations

import time

from common import keys
from common.errors import RequestTimeout
from common.messages import Ok
from services.cli.stop import StopOnInterrupt, send_stop

ROBOT = keys.DEFAULT_ROBOT


class Orchestrator:
    """Answers ``stop`` with the given replies in turn (an exception is raised); records what was sent."""

    def __init__(self, *answers: object, delay_s: float = 0.0):
        self.answers = list(answers)
        self.sent: list[tuple[str, float]] = []
        self.delay_s = delay_s

    def __call__(self, key: str, timeout: float) -> object:
        self.sent.append((key, timeout))
        time.sleep(self.delay_s)
        answer = self.answers.pop(0)
        if isinstance(answer, Exception):
            raise answer
        return answer


def test_the_line_reports_what_the_arm_answered():
    confirmed = Orchestrator(Ok(info={"stopped": True, "arm": {"answered": True, "estopped": True, "ms": 4.2}}))
    assert send_stop(confirmed, ROBOT) == "acquisition stopped; the arm confirmed its e-stop in 4 ms"
    assert confirmed.sent == [(keys.orchestrator(ROBOT, "stop"), 5.0)]
    silent = Orchestrator(Ok(info={"stopped": True, "arm": {"answered": False, "code": "timeout", "ms": 2001.0}}))
    line = send_stop(silent, ROBOT)
    assert "did not answer its e-stop within 2001 ms (timeout)" in line and "confirmed" not in line
    refused = Orchestrator(Ok(info={"stopped": True, "arm": {"answered": True, "estopped": False, "ms": 9.0,
                                                              "message": "joint3 did not take the hold"}}))
    assert "did NOT confirm its e-stop: joint3 did not take the hold" in send_stop(refused, ROBOT)


def test_no_answer_from_the_orchestrator_is_stated_with_the_wait():
    gone = Orchestrator(RequestTimeout("no reply"))
    line = send_stop(gone, ROBOT, timeout_ms=1500)
    assert line == "no answer from the orchestrator to the stop within 1500 ms: nothing is confirmed"
    assert gone.sent[0][1] == 1.5


def test_a_second_ctrl_c_sends_the_stop_again_and_each_answer_is_printed():
    orch = Orchestrator(RequestTimeout("no reply"),
                        Ok(info={"stopped": True, "arm": {"answered": True, "estopped": True, "ms": 3.0}}),
                        delay_s=0.05)
    said: list[str] = []
    handler = StopOnInterrupt(orch, ROBOT, said.append, timeout_ms=1000)
    handler()
    handler.wait()
    handler()
    handler.wait()
    assert len(orch.sent) == 2 and handler.sent == 2
    assert not any("confirmed its e-stop" in s for s in said[:2])  # nothing claimed before an answer
    assert said[1] == "no answer from the orchestrator to the stop within 1000 ms: nothing is confirmed"
    assert "again" in said[2] and said[3] == "acquisition stopped; the arm confirmed its e-stop in 3 ms"
