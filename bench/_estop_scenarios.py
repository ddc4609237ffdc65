"""The e-stop of the real DYNAMIXEL driver on the emulated PAPRAS bus, in the situations where it used to wait.

Run by ``objscan bench estop --arm-backend dynamixel --emulate-bus``: the arm service is a real process with
the DYNAMIXEL driver on its emulated bus (every read and write through dynamixel-sdk), whose faults the bench
injects through the bus's fault file (``OBJSCAN_EMULATED_BUS_FAULTS``). Each scenario times ``arm/stop``
round trips (ms) and counts the stops sent and answered (an answer is any reply: ``Ok(estopped)`` or the
``estop_failed`` error that names a servo the hold could not reach):

- ``idle``: the arm standing still;
- ``streaming``: one stop per move, sent while the set-points stream;
- ``settling_blocked``: joint 1 blocked 0.15 rad short of its target, one stop per move, sent while the
  settle check waits for it;
- ``silent_servo``: joint 3 no longer answers; ``detected_ms`` is how long the state stream took to name
  it (at the first read attempt it missed), ``confirmed_ms`` until the driver's retries confirmed it and
  left it out of reads; then the stops are timed (each answered ``estop_failed`` naming the servo: the reply codes are
  counted);
- ``gripper_closing``: the gripper closing at 60 N, a stop when the opening passes 80 mm;
  ``gripper_travel_after_stop_mm``: the largest, over the runs, from where the hold put the fingers to
  where they are 1 s later (``gripper_travel_after_request_mm``: from the last state published before the
  stop was sent, which also counts the fingers' travel during that state's age and the stop's round trip).
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from common import keys
from common.api import GripperRequest, MoveRequest
from common.client import request_sync
from common.codec import decode
from common.errors import ObjscanError, RemoteError
from common.messages import Error, JointState, Ok, Request
from services.arm.drivers.dynamixel.emulator import write_faults

BLOCK_RAD = 0.15
SLOW_MS = 30_000.0  # a stop not answered counts as this


class _Arm:
    """The bench's handle on the arm: requests, its state stream, the bus's fault file."""

    def __init__(self, session: Any, robot: str, fault_file: Path):
        self.session, self.robot, self.fault_file = session, robot, fault_file
        self.latest: JointState | None = None
        self.history: list[JointState] = []
        self._lock = threading.Lock()
        self._sub = session.declare_subscriber(keys.arm(robot, "state"), self._on_state)

    def _on_state(self, sample: Any) -> None:
        try:
            msg = decode(sample.payload.to_bytes())
        except Exception:  # noqa: BLE001 - a bench: an undecodable sample is skipped
            return
        if isinstance(msg, JointState):
            with self._lock:
                self.latest = msg
                self.history.append(msg)
                del self.history[:-500]

    def close(self) -> None:
        self._sub.undeclare()

    def request(self, key: str, msg: Any = None, timeout: float = 60.0) -> Any:
        return request_sync(self.session, keys.arm(self.robot, key), msg, timeout=timeout)

    def faults(self, faults: dict) -> None:
        write_faults(self.fault_file, faults)

    def stop(self) -> tuple[float, Any]:
        """One timed ``arm/stop``: (ms, the reply or the error)."""
        t0 = time.perf_counter()
        try:
            reply: Any = self.request("stop", timeout=SLOW_MS / 1e3)
        except ObjscanError as exc:
            reply = exc
        return (time.perf_counter() - t0) * 1e3, reply

    def reset(self) -> None:
        self.request("stop", Request(params={"reset": True}), timeout=30)

    def move(self, q: np.ndarray, timeout: float = 120.0) -> Any:
        try:
            return self.request("move", MoveRequest(kind="joints", q=q), timeout=timeout)
        except ObjscanError as exc:
            return exc

    def move_in_background(self, q: np.ndarray) -> threading.Thread:
        t = threading.Thread(target=self.move, args=(q,), daemon=True)
        t.start()
        return t


def _answered(reply: Any) -> str | None:
    """The reply's code when the arm answered (Ok or a typed error), else None."""
    if isinstance(reply, Ok):
        return "estopped" if reply.info.get("estopped") is True else "ok"
    if isinstance(reply, Error | RemoteError) and getattr(reply, "code", "") not in ("", "timeout"):
        return reply.code
    return None


def _block(times: list[float], codes: list[str | None], **extra: Any) -> dict[str, Any]:
    arr = np.asarray(times) if times else np.asarray([SLOW_MS])
    return {"estop_ms_p50": round(float(np.percentile(arr, 50)), 2),
            "estop_ms_p99": round(float(np.percentile(arr, 99)), 2),
            "estop_ms_max": round(float(arr.max()), 2),
            "sent": len(times), "answered": sum(c is not None for c in codes),
            "replies": dict(Counter(c or "none" for c in codes)), **extra}


def _timed(arm: _Arm, times: list[float], codes: list[str | None]) -> Any:
    ms, reply = arm.stop()
    code = _answered(reply)
    times.append(ms if code is not None else SLOW_MS)
    codes.append(code)
    return reply


def idle(arm: _Arm, n: int) -> dict[str, Any]:
    times: list[float] = []
    codes: list[str | None] = []
    for _ in range(n):
        _timed(arm, times, codes)
        time.sleep(0.02)
    arm.reset()
    return _block(times, codes)


def streaming(arm: _Arm, home: np.ndarray, n: int) -> dict[str, Any]:
    times: list[float] = []
    codes: list[str | None] = []
    away = home + np.array([0.5, -0.25, 0.25, 0.4, -0.3, 0.5])
    for k in range(n):
        t = arm.move_in_background(away if k % 2 == 0 else home)
        time.sleep(0.4 + 0.02 * (k % 5))  # planned and streaming
        _timed(arm, times, codes)
        t.join(timeout=60)
        arm.reset()
    arm.move(home)
    return _block(times, codes)


def settling_blocked(arm: _Arm, home: np.ndarray, n: int) -> dict[str, Any]:
    times: list[float] = []
    codes: list[str | None] = []
    target = home + np.array([0.45, 0.0, 0.0, 0.0, 0.0, 0.0])
    planned = arm.request("move", MoveRequest(kind="joints", q=target, dry_run=True)).duration_s
    for _ in range(n):
        arm.faults({1: {"block_short_rad": BLOCK_RAD}})
        t = arm.move_in_background(target)
        time.sleep(planned + 0.4)  # the stream ended; the settle check waits for the blocked joint
        _timed(arm, times, codes)
        t.join(timeout=60)
        arm.faults({})
        arm.reset()
        arm.move(home)
    return _block(times, codes, blocked_rad=BLOCK_RAD, after_stream_s=0.4)


def silent_servo(arm: _Arm, n: int) -> dict[str, Any]:
    times: list[float] = []
    codes: list[str | None] = []
    with arm._lock:
        arm.history.clear()
    t0 = time.perf_counter()
    arm.faults({3: {"silent": True}})
    detected_ms = confirmed_ms = None
    while time.perf_counter() - t0 < 10.0 and confirmed_ms is None:
        with arm._lock:
            named = [m.fault for m in arm.history
                     if m.fault.get("code") == "servo_silent" and 3 in m.fault.get("ids", [])]
        if named and detected_ms is None:
            detected_ms = round((time.perf_counter() - t0) * 1e3, 1)
        if any(f.get("confirmed", True) for f in named):
            confirmed_ms = round((time.perf_counter() - t0) * 1e3, 1)
        time.sleep(0.002)
    named_in_reply = 0
    for _ in range(n):
        reply = _timed(arm, times, codes)
        if isinstance(reply, RemoteError) and reply.code == "estop_failed" and any(
                s.get("id") == 3 for s in reply.detail.get("servos", [])):
            named_in_reply += 1
        time.sleep(0.02)
    arm.faults({})
    time.sleep(0.1)
    arm.reset()
    return _block(times, codes, detected_ms=detected_ms, confirmed_ms=confirmed_ms,
                  replies_naming_the_servo=named_in_reply,
                  silent_servo_id=3)


def gripper_closing(arm: _Arm, n: int) -> dict[str, Any]:
    times: list[float] = []
    codes: list[str | None] = []
    held_mm, after_stop, after_request = [], [], []
    for _ in range(n):
        arm.request("gripper", GripperRequest(opening=0.106, force=20.0), timeout=60)
        t = threading.Thread(target=_quiet, args=(arm.request, "gripper", GripperRequest(opening=0.0, force=60.0)),
                             daemon=True)
        t.start()
        deadline = time.monotonic() + 10.0
        last = None
        while time.monotonic() < deadline:
            last = arm.latest
            if last is not None and last.gripper_opening <= 0.080:
                break
            time.sleep(0.001)
        before = float(last.gripper_opening) if last is not None else float("nan")
        reply = _timed(arm, times, codes)
        held = float(reply.info.get("gripper_opening", float("nan"))) if isinstance(reply, Ok) else float("nan")
        t.join(timeout=30)
        time.sleep(1.0)
        after = float(arm.request("state", timeout=10).gripper_opening)
        arm.reset()
        held_mm.append(held * 1e3)
        after_stop.append(abs(held - after) * 1e3)
        after_request.append(abs(before - after) * 1e3)
    arm.request("gripper", GripperRequest(opening=0.106, force=20.0), timeout=60)
    return _block(times, codes, stop_at_opening_mm=[round(v, 2) for v in held_mm],
                  gripper_travel_after_stop_mm=round(float(np.max(after_stop)), 3),
                  gripper_travel_after_request_mm=round(float(np.max(after_request)), 3))


def _quiet(fn: Any, *args: Any) -> None:
    try:
        fn(*args)
    except ObjscanError:  # the e-stop ends the gripper motion: expected
        pass


def run_scenarios(session: Any, robot: str, fault_file: Path, home: np.ndarray, quick: bool) -> dict[str, Any]:
    arm = _Arm(session, robot, fault_file)
    try:
        time.sleep(0.5)  # the state subscription is live
        arm.reset()
        arm.move(home)
        return {
            "idle": idle(arm, 50 if quick else 200),
            "streaming": streaming(arm, home, 10 if quick else 30),
            "settling_blocked": settling_blocked(arm, home, 5 if quick else 15),
            "silent_servo": silent_servo(arm, 50 if quick else 200),
            "gripper_closing": gripper_closing(arm, 3 if quick else 10),
        }
    finally:
        arm.faults({})
        arm.close()
