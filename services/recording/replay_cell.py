"""Camera and arm services that answer from a recording: the robot half of a full replay.

A full replay re-runs the orchestrator, registration and grasp planning live, and needs the cell to
behave exactly as it did. The session folder's ``replay`` camera and arm backends cannot do that alone:
the camera serves view folders in order (the locate frame lives elsewhere, a re-scan's first attempt is
moved aside), and the arm refuses every motion. The recording holds what is needed: every request the
orchestrator made of the camera and the arm, in order, with the reply it got (failures included).

So these services answer each request on a key with the **next recorded reply on that key**, after
checking that the request is the recorded one: same type, same strings and flags, numbers within
``atol`` (default 1e-4: 0.1 mm, 0.1 mrad for poses). A request that differs means the live part of
the pipeline (registration, grasp planning) decided differently than in the recording; serving the
recorded reply would then be a lie, so the service refuses it with ``replay_diverged`` — and every
request after it, so the run ends quickly with a clear reason instead of wandering. No motion is ever
made. Health reports how many replies were served, the largest deviation seen and any divergence.

Run as ``python -m services.recording.replay_cell --role camera|arm --recording FILE.mcap``
(``--recording`` repeats for the parts of a resumed session).
"""

from __future__ import annotations

import dataclasses
import threading
from pathlib import Path
from typing import Any

import numpy as np

from common import keys
from common.codec import Message
from common.errors import ObjscanError
from common.messages import Error, JointState, Ok
from common.runtime import COMMAND_BUDGET, QueryContext, Service, run_service, service_arg_parser, settings_from_args
from services.arm.robot import JOINT_NAMES
from services.recording.errors import ReplayDiverged, ReplayExhausted
from services.recording.reader import Exchange, read_recording

DEFAULT_ATOL = 1e-4


def request_difference(recorded: Any, live: Any, atol: float = DEFAULT_ATOL, path: str = "") -> tuple[list[str], float]:
    """(fields that differ beyond ``atol``, largest numeric deviation) between two requests."""
    if isinstance(recorded, Message) or isinstance(live, Message):
        if type(recorded) is not type(live):
            return [f"{path or 'message'}: {type(recorded).__name__} != {type(live).__name__}"], 0.0
        diffs: list[str] = []
        worst = 0.0
        for f in dataclasses.fields(recorded):
            d, w = request_difference(getattr(recorded, f.name), getattr(live, f.name), atol, f"{path}.{f.name}")
            diffs += d
            worst = max(worst, w)
        return diffs, worst
    if isinstance(recorded, np.ndarray) or isinstance(live, np.ndarray):
        a, b = np.asarray(recorded), np.asarray(live)
        if recorded is None or live is None or a.shape != b.shape:
            return [f"{path}: shape {getattr(a, 'shape', None)} != {getattr(b, 'shape', None)}"], 0.0
        if a.size == 0:
            return [], 0.0
        if a.dtype.kind in "fc" or b.dtype.kind in "fc":
            w = float(np.max(np.abs(a.astype(np.float64) - b.astype(np.float64))))
            return ([f"{path}: differs by {w:.3g}"] if not w <= atol else []), w
        return ([] if np.array_equal(a, b) else [f"{path}: values differ"]), 0.0
    if isinstance(recorded, dict) and isinstance(live, dict):
        if set(recorded) != set(live):
            return [f"{path}: keys {sorted(recorded)} != {sorted(live)}"], 0.0
        diffs, worst = [], 0.0
        for k in recorded:
            d, w = request_difference(recorded[k], live[k], atol, f"{path}.{k}")
            diffs += d
            worst = max(worst, w)
        return diffs, worst
    if isinstance(recorded, (list, tuple)) and isinstance(live, (list, tuple)):
        if len(recorded) != len(live):
            return [f"{path}: length {len(recorded)} != {len(live)}"], 0.0
        diffs, worst = [], 0.0
        for i, (x, y) in enumerate(zip(recorded, live, strict=True)):
            d, w = request_difference(x, y, atol, f"{path}[{i}]")
            diffs += d
            worst = max(worst, w)
        return diffs, worst
    if isinstance(recorded, float) or isinstance(live, float):
        if isinstance(recorded, bool) or isinstance(live, bool) or recorded is None or live is None:
            return ([] if recorded == live else [f"{path}: {recorded!r} != {live!r}"]), 0.0
        w = abs(float(recorded) - float(live))
        return ([f"{path}: {recorded!r} != {live!r}"] if not w <= atol else []), w
    return ([] if recorded == live else [f"{path}: {recorded!r} != {live!r}"]), 0.0


class RecordedReplies:
    """Per key, the recorded exchanges in order; ``answer`` checks a live request and returns the reply."""

    def __init__(self, exchanges: list[Exchange], atol: float = DEFAULT_ATOL):
        self.atol = atol
        self._queues: dict[str, list[Exchange]] = {}
        for ex in exchanges:
            reply = ex.reply_message()
            if isinstance(reply, Error) and reply.detail.get("local"):
                continue  # nobody answered (service restarting): the orchestrator retried, the retry follows
            self._queues.setdefault(ex.key, []).append(ex)
        self._next: dict[str, int] = {k: 0 for k in self._queues}
        self.served = 0
        self.max_deviation = 0.0
        self.diverged: dict[str, Any] | None = None
        self._lock = threading.Lock()

    def remaining(self, key: str) -> int:
        return len(self._queues.get(key, [])) - self._next.get(key, 0)

    def answer(self, key: str, request: Message | None) -> Message:
        """The recorded reply to ``request`` on ``key``; raises the recorded error, or a replay error."""
        with self._lock:
            if self.diverged is not None:
                raise ReplayDiverged("the replay diverged earlier; refusing every further request",
                                     detail=self.diverged)
            queue = self._queues.get(key, [])
            i = self._next.get(key, 0)
            if i >= len(queue):
                raise ReplayExhausted(f"the recording holds only {len(queue)} replies on {key}",
                                      detail={"key": key, "recorded": len(queue)})
            ex = queue[i]
            recorded = ex.request_message()
            diffs, worst = request_difference(recorded, request, self.atol)
            if diffs:
                self.diverged = {"key": key, "index": i, "differences": diffs[:10], "max_deviation": worst}
                raise ReplayDiverged(f"request {i} on {key} differs from the recording: {'; '.join(diffs[:3])}",
                                     detail=self.diverged)
            self._next[key] = i + 1
            self.served += 1
            self.max_deviation = max(self.max_deviation, worst)
        reply = ex.reply_message()
        if isinstance(reply, Error):
            raise ObjscanError(reply.message, code=reply.code, detail={**reply.detail, "replayed": True})
        return reply

    def figures(self) -> dict[str, Any]:
        return {"served": self.served, "max_deviation": self.max_deviation, "diverged": self.diverged,
                "remaining": {k: self.remaining(k) for k in self._queues}}


class ReplayCellService(Service):
    """The camera or the arm of a recorded cell (``role``), answering from the recording."""

    def __init__(self, role: str, recordings: list[Path], atol: float, settings: Any = None):
        self.name = role
        super().__init__(settings)
        self.role = role
        self.recordings = recordings
        self.atol = atol

    async def setup(self) -> None:
        r = self.robot
        exchanges: list[Exchange] = []
        for path in self.recordings:
            exchanges += read_recording(path).exchanges
        mine = ({keys.camera_capture(r)} if self.role == "camera"
                else {keys.arm(r, op) for op in ("move", "gripper", "scene", "stop", "state")})
        self.replies = RecordedReplies([e for e in exchanges if e.key in mine], self.atol)
        if self.role == "camera":
            self.queryable(keys.camera_capture(r), self._answer)
        else:
            for op in ("move", "gripper", "scene"):
                self.queryable(keys.arm(r, op), self._answer)
            self.queryable(keys.arm(r, "stop"), self._stop, budget=COMMAND_BUDGET, priority=True)
            self.queryable(keys.arm(r, "state"), self._state)
            self.state_pub = self.publisher(keys.arm(r, "state"), block=False)
        self.last_state: JointState | None = None

    async def _answer(self, msg: Message | None, ctx: QueryContext) -> Message:
        reply = self.replies.answer(ctx.key, msg)
        q = getattr(reply, "q", None)
        if self.role == "arm" and q is not None and getattr(reply, "T_base_gripper", None) is not None:
            self.last_state = JointState(names=list(JOINT_NAMES[:len(q)]),
                                         position=np.asarray(q, np.float64), T_base_gripper=reply.T_base_gripper,
                                         T_base_camera=reply.T_base_camera)
            self.state_pub.put(self.last_state)
        return reply

    async def _stop(self, msg: Message | None, ctx: QueryContext) -> Message:
        """A stop always succeeds (nothing moves); a recorded stop is consumed so the order stays right."""
        if self.replies.remaining(ctx.key) > 0:
            try:
                return self.replies.answer(ctx.key, msg)
            except ObjscanError:
                pass
        return Ok(info={"estopped": True, "replay": True})

    async def _state(self, msg: Message | None, ctx: QueryContext) -> Message:
        """The orchestrator's recorded state queries are answered in order (they decide escapes); past
        them, the state after the last move served."""
        if self.replies.remaining(ctx.key) > 0:
            return self.replies.answer(ctx.key, msg)
        if self.last_state is None:
            raise ObjscanError("no recorded state served yet", code="no_state")
        return self.last_state

    def health_info(self) -> dict[str, object]:
        return {"backend": "recording", "recordings": [str(p) for p in self.recordings], **self.replies.figures()}


def main() -> None:
    p = service_arg_parser("objscan replay cell: camera or arm answering from a recorded session (MCAP)")
    p.add_argument("--role", choices=["camera", "arm"], required=True)
    p.add_argument("--recording", action="append", required=True, help="MCAP file (repeat for parts, in order)")
    p.add_argument("--atol", type=float, default=DEFAULT_ATOL,
                   help="largest difference between a live and a recorded request number (default: %(default)s)")
    args = p.parse_args()
    run_service(lambda: ReplayCellService(args.role, [Path(r) for r in args.recording], args.atol,
                                          settings_from_args(args)))


if __name__ == "__main__":
    main()
