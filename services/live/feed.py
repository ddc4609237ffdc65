"""Feeding the live view: a cell's Zenoh streams while it scans, or a recorded session afterwards.

``LiveView`` owns the sinks (Rerun, Foxglove) and the one ``SceneInterpreter``; ``subscribe`` joins a
cell (the orchestrator's tap, the arm's joint state and the orchestrator's status), ``replay_recording``
reads a session's recording and sends the same exchanges and samples in their recorded order, so a
replayed scan looks exactly like the live one. Zenoh callbacks only enqueue raw bytes; one worker
thread decodes and draws, so a slow viewer never holds up Zenoh.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from pathlib import Path
from typing import Any, Protocol

from common import keys
from common.codec import decode
from common.errors import ObjscanError
from common.log import event as log_event
from common.messages import Request
from services.live import scene
from services.live.tap import tap_key

log = logging.getLogger("objscan.live")


class Sink(Protocol):
    def handle(self, event: scene.Event) -> None: ...

    def close(self) -> None: ...


class LiveView:
    """Fans scene events out to every sink; thread-safe ``exchange``/``sample``; ``close`` ends the sinks."""

    def __init__(self, sinks: list[Sink], *, state_rate_hz: float = 10.0):
        self.sinks = sinks
        self.state_rate_hz = state_rate_hz
        self.scene = scene.SceneInterpreter(state_rate_hz)
        self.events: dict[str, int] = {}  # event type -> count drawn (what a caller can report)
        self._lock = threading.Lock()
        self._queue: queue.Queue[tuple[str, str, bytes] | None] = queue.Queue(maxsize=2000)
        self._worker: threading.Thread | None = None
        self._subs: list[Any] = []

    def _draw(self, events: list[scene.Event]) -> None:
        for ev in events:
            self.events[type(ev).__name__] = self.events.get(type(ev).__name__, 0) + 1
            for sink in self.sinks:
                try:
                    sink.handle(ev)
                except Exception as exc:  # a viewer going away must not end the scan it watches
                    log_event(log, "live sink failed", logging.WARNING, sink=type(sink).__name__, error=str(exc))

    def reset(self) -> None:
        """Forget the scene's state (view number, pending grasp): a replay starts over."""
        with self._lock:
            self.scene = scene.SceneInterpreter(self.state_rate_hz)

    def exchange(self, t: float, key: str, request: Any, reply: Any) -> None:
        with self._lock:
            self._draw(self.scene.exchange(t, key, request, reply))

    def sample(self, t: float, msg: Any) -> None:
        with self._lock:
            self._draw(self.scene.sample(t, msg))

    # ------------------------------------------------------------------ live: a cell's Zenoh streams
    def subscribe(self, zenoh_session: Any, robot: str = keys.DEFAULT_ROBOT) -> None:
        """Follow a cell: the orchestrator's tap (exchanges), the arm's state and the orchestrator's status."""
        self._worker = threading.Thread(target=self._run, name="live-view", daemon=True)
        self._worker.start()
        for key in (tap_key(robot), keys.arm(robot, "state"), keys.orchestrator(robot, "status")):
            self._subs.append(zenoh_session.declare_subscriber(key, self._enqueue(key)))

    def _enqueue(self, key: str) -> Any:
        def on_sample(sample: Any) -> None:  # zenoh thread: hand over the bytes, nothing else
            try:
                self._queue.put_nowait((key, str(sample.key_expr), sample.payload.to_bytes()))
            except queue.Full:
                self.events["dropped"] = self.events.get("dropped", 0) + 1
        return on_sample

    def _run(self) -> None:
        while (item := self._queue.get()) is not None:
            key, _, payload = item
            try:
                msg = decode(payload)
            except ObjscanError:
                continue  # a malformed sample is the sender's problem; the view shows the rest
            if key.endswith("/tap") and isinstance(msg, Request):
                p = msg.params
                self.exchange(float(p.get("t_received", time.time())), str(p.get("key")), p.get("request"),
                              p.get("reply"))
            else:
                self.sample(float(getattr(msg, "stamp", 0.0) or time.time()), msg)

    def close(self, timeout: float = 30.0) -> None:
        """Stop following, draw what is queued, then close every sink."""
        for sub in self._subs:
            sub.undeclare()
        self._subs.clear()
        if self._worker is not None:
            self._queue.put(None)
            self._worker.join(timeout)
            self._worker = None
        for sink in self.sinks:
            sink.close()


def replay_recording(source: str | Path, view: LiveView, *, speed: float | None = None) -> dict[str, int]:
    """Send a recorded session (folder or ``.mcap``) through ``view`` in recorded order; return event counts.

    ``speed``: None sends everything at once (a file sink); a number paces the replay at that multiple of
    the recorded time (a WebSocket viewer sees it unfold like the live scan).
    """
    from services.recording.reader import read_recording

    rec = read_recording(source)
    items: list[tuple[float, int, Any]] = [(ex.t_received, 0, ex) for ex in rec.exchanges]
    for topic, samples in rec.samples.items():
        if topic.endswith("/arm/state") or topic.endswith("/orchestrator/status"):
            items += [(t, 1, payload) for t, payload in samples]
    items.sort(key=lambda it: (it[0], it[1]))
    t0, w0 = (items[0][0] if items else 0.0), time.monotonic()
    for t, kind, item in items:
        if speed:
            time.sleep(max(0.0, (t - t0) / speed - (time.monotonic() - w0)))
        try:
            if kind == 0:
                view.exchange(t, item.key, item.request_message(), item.reply_message())
            else:
                view.sample(t, decode(item))
        except ObjscanError:
            continue  # an undecodable record shows nothing; the rest of the session still replays
    return dict(view.events)
