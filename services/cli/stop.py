"""What Ctrl-C does to a scan the CLI follows: send the orchestrator's ``stop``, and say what came back.

Nothing is claimed before it is confirmed: the line printed is built from the orchestrator's reply, which
carries the arm's own answer to its e-stop (``arm``: ``answered``, ``estopped``, ``ms``, or the error), or
says that no answer came within the stated wait. Every Ctrl-C sends the stop again (a stop that was lost,
or an arm that did not answer the first time, gets another chance); each is sent from its own thread so the
progress display goes on, and the scan waits for the pending answers before it prints its summary.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from common import keys
from common.errors import ObjscanError

STOP_ANSWER_MS = 5000
"""How long the CLI waits for the orchestrator's answer to a stop (it waits at most ~3 s for the arm)."""

Requester = Callable[[str, float], Any]  # (key, timeout_s) -> reply message; raises ObjscanError


def describe_stop(info: dict[str, Any]) -> str:
    """One line for the orchestrator's reply to ``stop``: the acquisition stopped, and the arm's answer."""
    arm = info.get("arm")
    head = "acquisition stopped"
    if not isinstance(arm, dict):
        return f"{head}; the orchestrator did not report the arm's answer to its e-stop"
    ms = float(arm.get("ms", 0.0))
    if arm.get("answered") and arm.get("estopped") is True:
        return f"{head}; the arm confirmed its e-stop in {ms:.0f} ms"
    if arm.get("answered"):
        why = arm.get("message") or {k: v for k, v in arm.items() if k not in ("answered", "ms")}
        return f"{head}; the arm answered in {ms:.0f} ms but did NOT confirm its e-stop: {why}"
    return (f"{head}; the arm did not answer its e-stop within {ms:.0f} ms ({arm.get('code', 'no answer')}): "
            "it may still be moving, use the hardware e-stop")


def send_stop(request: Requester, robot: str, timeout_ms: int = STOP_ANSWER_MS) -> str:
    """Send ``orchestrator/stop`` once and return the line that reports its outcome."""
    t0 = time.monotonic()
    try:
        reply = request(keys.orchestrator(robot, "stop"), timeout_ms / 1000.0)
    except ObjscanError as exc:
        waited = (time.monotonic() - t0) * 1000.0
        if exc.code in ("timeout", "unavailable") or waited >= 0.95 * timeout_ms:
            return f"no answer from the orchestrator to the stop within {timeout_ms} ms: nothing is confirmed"
        return f"the orchestrator did not stop: {exc.message} [{exc.code}]"
    info = getattr(reply, "info", None)
    return describe_stop(info if isinstance(info, dict) else {})


class StopOnInterrupt:
    """A SIGINT handler: every call sends the stop again and prints its outcome when it comes."""

    def __init__(self, request: Requester, robot: str, say: Callable[[str], None],
                 timeout_ms: int = STOP_ANSWER_MS):
        self.request, self.robot, self.say, self.timeout_ms = request, robot, say, timeout_ms
        self.sent = 0
        self.outcomes: list[str] = []
        self._threads: list[threading.Thread] = []

    def __call__(self, *_: object) -> None:
        self.sent += 1
        again = " again" if self.sent > 1 else ""
        self.say(f"stopping: stop sent{again} to the orchestrator, waiting for its answer "
                 f"(up to {self.timeout_ms} ms; Ctrl-C sends it again)")
        t = threading.Thread(target=self._send, name=f"stop-{self.sent}", daemon=True)
        self._threads.append(t)
        t.start()

    def _send(self) -> None:
        line = send_stop(self.request, self.robot, self.timeout_ms)
        self.outcomes.append(line)
        self.say(line)

    def wait(self) -> None:
        """Wait for the answers of the stops sent (each is bounded by its own timeout)."""
        for t in self._threads:
            t.join(self.timeout_ms / 1000.0 + 1.0)
