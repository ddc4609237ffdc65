"""The orchestrator's view of the robot cell: one async method per service call.

It knows keys and message types, nothing about the acquisition's logic; the state machine talks only to
this, so the same machine drives the simulated cell, the real one or a replay.

Every call is idempotent (a move to a pose, a capture, a registration of given frames), so when a service
is gone — killed, restarting, its machine rebooting — the call waits for it to come back (up to
``retry_window_s``) and is sent again. The same holds when the service answers but one *it* depends on is
gone (``RemoteError`` with code ``unavailable``/``timeout``/``shutdown``: the camera while the twin it
renders through restarts); a capture that failed saved nothing, so sending it again cannot duplicate a
frame (the machine writes a frame only from a reply). ``tap`` sees every request and reply (the session recorder).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable
from typing import Any

import numpy as np

from common import keys
from common.api import (
    CaptureRequest,
    DynamicRequest,
    EdgeReply,
    EdgeRequest,
    GraspPlanReply,
    GraspRequest,
    GripperRequest,
    GripperResult,
    ModelResult,
    MoveRequest,
    MoveResult,
    SceneRequest,
    StaticRequest,
    ViewResult,
)
from common.codec import Message
from common.errors import ObjscanError, RemoteError, ServiceUnavailable
from common.log import event
from common.messages import JointState, Ok, Plane, PointCloud, Request, RGBDFrame

log = logging.getLogger("objscan.orchestrator")

Requester = Callable[..., Awaitable[Message]]
Tap = Callable[[str, Message | None, Message, float, float], None]

MOVE_TIMEOUT_S = 120.0
COMPUTE_TIMEOUT_S = 600.0
ESTOP_ANSWER_S = 2.0  # how long a stop waits for the arm's answer (one attempt, no retry)
POSE_ATTEMPTS = 3  # captures tried for a frame with a camera pose (a real camera asks the arm for it)


def _expect(reply: Message, cls: type) -> Any:
    if not isinstance(reply, cls):
        raise RemoteError(f"expected {cls.__name__}, got {type(reply).__name__}", code="bad_reply")
    return reply


class Cell:
    """Async calls to the services of one robot cell (``robot``) and the shared compute services."""

    def __init__(self, request: Requester, robot: str, *, retry_window_s: float = 120.0, tap: Tap | None = None):
        self._send = request
        self.robot = robot
        self.retry_window_s = retry_window_s
        self.tap = tap
        self.retries = 0
        self.twin_seen = False  # a twin answered once: later silence on sim/world means it is restarting

    async def _request(self, key: str, msg: Message | None = None, *, timeout: float) -> Message:
        """Send, and re-send while the service is unavailable (it may be restarting)."""
        deadline = time.monotonic() + self.retry_window_s
        delay = 0.5
        while True:
            t0 = time.time()
            try:
                reply = await self._send(key, msg, timeout=timeout)
            except ServiceUnavailable as exc:  # includes timeouts: the service died mid-request
                # sim/world: no answer before any twin answered means a real cell (the machine branches on
                # it at session start); after that it is a twin restarting, worth waiting for
                if time.monotonic() > deadline or (key.endswith("/sim/world") and not self.twin_seen):
                    raise
                why, code = "service unavailable", exc.code
            except RemoteError as exc:
                # the service answered but one it depends on is gone (e.g. the camera's twin restarting), or
                # the arm is still finishing a motion an earlier orchestrator started (it refuses, not queues)
                if not (exc.transient or exc.code == "busy") or time.monotonic() > deadline:
                    raise
                why = "the arm is still finishing a motion" if exc.code == "busy" else \
                    "a service behind the reply is unavailable"
                code = exc.code
            else:
                if self.tap is not None:
                    self.tap(key, msg, reply, t0, time.time())
                return reply
            self.retries += 1
            event(log, f"{why}; retrying", logging.WARNING, key=key, code=code)
            await asyncio.sleep(delay)
            delay = min(delay * 2, 5.0)

    async def move(self, kind: str, *, target: np.ndarray | None = None, q: np.ndarray | None = None,
                   frame: str = "gripper", speed: float = 0.5, free_roll: bool = False,
                   contact: bool = False, dry_run: bool = False, check_opening: float | None = None
                   ) -> MoveResult:
        msg = MoveRequest(kind=kind, target=target, q=q, frame=frame, speed_scale=speed, free_roll=free_roll,
                          allow_object_contact=contact, dry_run=dry_run,
                          check_opening=-1.0 if check_opening is None else float(check_opening))
        return _expect(await self._request(keys.arm(self.robot, "move"), msg, timeout=MOVE_TIMEOUT_S), MoveResult)

    async def gripper(self, opening: float, force: float = 30.0) -> GripperResult:
        reply = await self._request(keys.arm(self.robot, "gripper"), GripperRequest(opening=opening, force=force),
                                    timeout=MOVE_TIMEOUT_S)
        return _expect(reply, GripperResult)

    async def set_object_box(self, center: np.ndarray, extent: np.ndarray) -> None:
        await self._request(keys.arm(self.robot, "scene"), SceneRequest(center=center, extent=extent), timeout=10.0)

    async def clear_object_box(self) -> None:
        await self.set_object_box(np.zeros(3), np.zeros(3))

    async def state(self) -> JointState:
        return _expect(await self._request(keys.arm(self.robot, "state"), timeout=10.0), JointState)

    async def estop(self) -> None:
        await self._request(keys.arm(self.robot, "stop"), timeout=5.0)

    async def estop_once(self, timeout: float = ESTOP_ANSWER_S) -> dict[str, Any]:
        """Send the arm one e-stop and say what came back, within ``timeout``: never the retry loop.

        A stop is only worth something now: waiting for an unavailable arm to come back (the retry window
        of every other call) would hold the caller for minutes and say nothing true. The result is the
        arm's own answer (``answered: True`` with its ``estopped`` and whatever else it said) or why none
        came (``answered: False`` with the error's ``code`` and ``message``), with the wait in ``ms``."""
        key = keys.arm(self.robot, "stop")
        t0, wall = time.monotonic(), time.time()
        try:
            reply = await self._send(key, None, timeout=timeout)
        except ObjscanError as exc:
            # an error the arm itself sent (its stop failed) is an answer; silence or a timeout is not
            answered = isinstance(exc, RemoteError) and not exc.transient
            return {"answered": answered, **({"estopped": False} if answered else {}), "code": exc.code,
                    "message": exc.message, "ms": round((time.monotonic() - t0) * 1000.0, 1)}
        ms = round((time.monotonic() - t0) * 1000.0, 1)
        if self.tap is not None:
            self.tap(key, None, reply, wall, time.time())
        info = dict(reply.info) if isinstance(reply, Ok) and isinstance(reply.info, dict) else {}
        return {**info, "answered": True, "ms": ms}

    async def reset_estop(self) -> None:
        await self._request(keys.arm(self.robot, "stop"), Request(params={"reset": True}), timeout=5.0)

    async def capture(self, width: int, height: int) -> RGBDFrame:
        """A frame with a known camera pose. A frame stamped ``pose_source=unknown`` (a real camera whose
        pose query failed stamps the identity) is captured again, up to ``POSE_ATTEMPTS`` times, then
        refused with ``no_camera_pose``: it would be registered at the base origin."""
        for attempt in range(1, POSE_ATTEMPTS + 1):
            reply = await self._request(keys.camera_capture(self.robot), CaptureRequest(width=width, height=height),
                                        timeout=60.0)
            frame = _expect(reply, RGBDFrame)
            if (frame.meta or {}).get("pose_source") != "unknown":
                return frame
            event(log, "frame without a camera pose; capturing again", logging.WARNING, attempt=attempt)
            await asyncio.sleep(0.5 * attempt)
        raise ObjscanError(f"the camera could not stamp a pose in {POSE_ATTEMPTS} captures (pose_source=unknown)",
                           code="no_camera_pose")

    async def register_static(self, frames: list[RGBDFrame], view: int, profile: str,
                              pose_accuracy: dict | None = None) -> ViewResult:
        request = StaticRequest(frames=frames, profile=profile, view=view, pose_accuracy=dict(pose_accuracy or {}))
        reply = await self._request(keys.REGISTRATION_STATIC, request,
                                    timeout=COMPUTE_TIMEOUT_S)
        return _expect(reply, ViewResult)

    async def plan_grasps(self, cloud: PointCloud, table: Plane, mode: str) -> GraspPlanReply:
        reply = await self._request(keys.GRASP_PLAN, GraspRequest(cloud=cloud, table=table, mode=mode), timeout=60.0)
        return _expect(reply, GraspPlanReply)

    async def build_model(self, views: list[ViewResult], turns_deg: list[float], config: dict) -> ModelResult:
        reply = await self._request(keys.REGISTRATION_DYNAMIC,
                                    DynamicRequest(views=views, turns_deg=turns_deg, config=config),
                                    timeout=COMPUTE_TIMEOUT_S * 2)
        return _expect(reply, ModelResult)

    async def register_edge(self, request: EdgeRequest) -> EdgeReply:
        """One edge of the incremental model: its views go to registration, which builds, fingerprints and
        runs the edge's pair jobs on its workers; the reply is their results, ready to store."""
        reply = await self._request(keys.REGISTRATION_EDGE, request, timeout=COMPUTE_TIMEOUT_S)
        return _expect(reply, EdgeReply)

    # ---------------------------------------------------------------------------- digital twin only
    async def sim(self, op: str, **params: Any) -> dict[str, Any]:
        # a reset builds the world: with mujoco physics a new non-convex mesh is decomposed first (coacd,
        # seconds to a minute on a loaded machine, then cached), so it gets longer than other operations
        timeout = 300.0 if op == "reset" else 60.0
        reply = await self._request(keys.sim(self.robot, "world"), Request(params={"op": op, **params}),
                                    timeout=timeout)
        info = _expect(reply, Ok).info
        self.twin_seen = True
        return info
