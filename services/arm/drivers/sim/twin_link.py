"""How the arm's sim driver reaches the digital twin over Zenoh.

Every set-point goes to ``sim/joints`` as a request carrying the joints and the TCP/camera poses from
forward kinematics, so the twin moves a held object with the gripper and renders from where the camera
really is; requests keep set-points in order and make a move complete only once the twin has it.
Gripper commands go to ``sim/gripper``, whose answer (the opening the fingers reached on the object)
is what the driver reports back, so ``ArmController.gripper`` detects a grasp exactly as on hardware.

The twin may die and come back (docs/reliability.md). The arm is the authority on where the arm is, the
twin on the rest of the world (it reloads that from its state file), so:

- a set-point or gripper command the twin does not answer (no twin, or it died while serving) is sent
  again until it answers, for at most ``retry_window_s``: a move pauses while the twin restarts and then
  goes on (both are idempotent: the same set-point twice is one pose; the twin answers a repeated close
  with ``already_holding`` and a repeated open with ``opened``);
- when a twin's liveliness token appears, the current joints are sent at once (``resyncs`` counts it),
  so a restarted twin renders from the right camera pose even when the arm is standing still;
- a restarted *arm* starts where the twin says the arm is (when the twin knows), not at ``initial_q``:
  the twin is the arm's physical stand-in.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import numpy as np
import zenoh

from common import keys
from common.api import GripperRequest, GripperResult
from common.client import request_sync
from common.codec import Message
from common.errors import ObjscanError, RemoteError, ServiceUnavailable
from common.log import event
from common.messages import JointState, Ok, Request
from services.arm.drivers.sim.config import SimDriverConfig
from services.arm.drivers.sim.driver import SimArmDriver
from services.arm.kinematics import Kinematics

log = logging.getLogger("objscan.arm")


class TwinLinkedDriver(SimArmDriver):
    """The sim driver wired to the twin: joints with true poses out, measured gripper opening back."""

    def __init__(self, session: zenoh.Session, robot: str, kinematics: Kinematics,
                 config: SimDriverConfig | None = None, timeout: float = 10.0, retry_window_s: float = 90.0):
        self._session = session
        self._robot = robot
        self._kin = kinematics
        self._timeout = timeout
        self.retry_window_s = retry_window_s
        self.retries = 0
        self.resyncs = 0
        self._send_lock = threading.Lock()  # one send at a time, so the twin gets set-points in order
        self._resync_wanted = threading.Event()
        self._closing = threading.Event()
        self._watch: Any = None
        self._resync_thread: threading.Thread | None = None
        super().__init__(send=self._send_joints, config=config)

    # ------------------------------------------------------------------------------------ requests
    def _ask(self, op: str, msg: Message, timeout: float | None = None) -> Message:
        """One request to the twin, sent again while the twin is away (bounded by ``retry_window_s``)."""
        deadline = time.monotonic() + self.retry_window_s
        delay = 0.2
        while True:
            try:
                return request_sync(self._session, keys.sim(self._robot, op), msg, timeout=timeout or self._timeout)
            except (ServiceUnavailable, RemoteError) as exc:
                transient = isinstance(exc, ServiceUnavailable) or exc.transient
                if not transient or time.monotonic() + delay > deadline or self._closing.is_set():
                    raise
                self.retries += 1
                event(log, "twin not answering; sending again", logging.WARNING, op=op, code=exc.code)
                time.sleep(delay)
                delay = min(delay * 2, 2.0)

    def _joint_state(self, q: np.ndarray, opening: float) -> JointState:
        return JointState(names=list(self._kin.joint_names), position=np.asarray(q, dtype=np.float64),
                          T_base_gripper=self._kin.fk(q, "gripper"), T_base_camera=self._kin.fk(q, "camera"),
                          gripper_opening=float(opening))

    def _send_joints(self, q: np.ndarray, opening: float) -> None:
        with self._send_lock:
            self._ask("joints", self._joint_state(q, opening))

    def set_gripper(self, opening_m: float, force: float) -> None:
        self._require()
        reply = self._ask("gripper", GripperRequest(opening=float(opening_m), force=float(force)))
        assert isinstance(reply, GripperResult)
        with self._lock:
            self._opening, self._force = float(reply.opening), float(force)
        self.last_gripper = reply

    # ------------------------------------------------------------------------------- connect / close
    def _twin_arm_state(self) -> tuple[np.ndarray, float] | None:
        """Where the twin says this arm is (joints, opening), or None when it does not know / is not up."""
        try:
            reply = request_sync(self._session, keys.sim(self._robot, "world"), Request(params={"op": "state"}),
                                 timeout=self._timeout)
        except ObjscanError:
            return None
        info = reply.info if isinstance(reply, Ok) else {}
        names, pos = info.get("joint_names") or [], info.get("joint_positions") or []
        if list(names) != list(self._kin.joint_names) or len(pos) != len(names):
            return None
        q = np.asarray(pos, dtype=np.float64)
        opening = info.get("gripper_opening")
        if not np.all(np.isfinite(q)) or not isinstance(opening, (int, float)):
            return None
        return q, float(opening)

    def connect(self, wait_s: float = 120.0) -> None:
        """Connect once the twin answers (services start in any order); the twin learns where the arm is,
        or, when the twin already knows (this arm restarted), the arm starts from there."""
        super().connect()
        known = self._twin_arm_state()
        if known is not None:
            with self._lock:
                self._q, self._opening = known[0].copy(), known[1]
            event(log, "arm starts where the twin has it", q=np.round(known[0], 4).tolist())
        deadline = time.monotonic() + wait_s
        while True:
            try:
                request_sync(self._session, keys.sim(self._robot, "joints"), self._joint_state(self._q, self._opening),
                             timeout=self._timeout)
                break
            except ServiceUnavailable:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        self._watch_twin()

    def _watch_twin(self) -> None:
        """Re-send the joints whenever a twin's liveliness token appears (a restarted twin)."""
        if self._watch is not None:
            return
        self._closing.clear()

        def on_token(sample: zenoh.Sample) -> None:  # zenoh thread: no requests here, just a signal
            if sample.kind == zenoh.SampleKind.PUT:
                self._resync_wanted.set()

        self._watch = self._session.liveliness().declare_subscriber(keys.alive("sim", "*"), on_token)
        self._resync_thread = threading.Thread(target=self._resync_loop, name="twin-resync", daemon=True)
        self._resync_thread.start()

    def _resync_loop(self) -> None:
        while not self._closing.is_set():
            if not self._resync_wanted.wait(0.5):
                continue
            self._resync_wanted.clear()
            if self._closing.is_set():
                return
            try:
                self.resync()
            except Exception as exc:  # the twin went away again: its next token brings us back here
                event(log, "could not re-send the joints to the twin", logging.WARNING, error=repr(exc))

    def resync(self) -> None:
        """Send the current joints (and opening) to the twin: idempotent, safe in the middle of a move.

        Only the send lock is held (not the driver's state lock, so ``read_joints`` never waits on a twin
        that is away), and the latest set-point is read inside it: a set-point written meanwhile is sent
        after this one, so the twin always ends on the newest pose."""
        with self._send_lock:
            q, opening = self._q.copy(), self._opening
            self._ask("joints", self._joint_state(q, opening))
        self.resyncs += 1
        event(log, "joints re-sent to the twin", q=np.round(q, 4).tolist())

    def close(self) -> None:
        self._closing.set()
        self._resync_wanted.set()
        if self._watch is not None:
            try:
                self._watch.undeclare()
            except Exception:  # the session is already closed
                pass
            self._watch = None
        if self._resync_thread is not None:
            self._resync_thread.join(timeout=2.0)
            self._resync_thread = None
        super().close()
