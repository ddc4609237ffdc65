"""``SessionRecorder``: one acquisition's messages into one MCAP file, written as they happen.

What goes in (see docs/recording.md):

- **raw channels**, message encoding ``msgpack``, the exact codec payload of every message:
  every request the orchestrator sends on topic ``KEY?request`` and its reply on ``KEY?reply`` (an
  ``Error`` message when the service refused it, so a replay can reproduce failures too); request and
  reply of one exchange share the MCAP ``sequence``; ``publish_time`` is when the request was sent,
  ``log_time`` when its reply arrived. Stream samples (arm joint state, orchestrator status) go on a
  topic named by their Zenoh key with ``log_time`` = receive time, ``publish_time`` = the sample's own
  stamp when it has one. Every channel's metadata names its ``zenoh_key`` and ``kind``.
- **visual channels** in Foxglove's protobuf schemas (``services/recording/visual.py``).
- **metadata** records: ``session`` (object, profile, seed, the run's config), ``objscan`` (version,
  wire schema versions), ``recording`` (conventions), and ``closed`` (counts) when closed cleanly.

Crash safety: a writer thread owns the file; it ends the open chunk and flushes the stream after every
exchange and at least every ``flush_interval_s``, so a killed orchestrator leaves everything up to the
last flush on disk. Such a file has no summary/footer: ``read_recording`` reads it anyway and
``recover()`` rewrites it into a complete file. The tap and the subscriber callbacks only enqueue,
so recording never blocks the orchestrator's event loop (encoding and compression happen off it).

Bounded: a stream sample is recorded only within its key's ``Budget`` (``STREAM_BUDGETS``: the arm's
joint state 64 kB, like a command; or ``subscribe(..., budgets=)``). The size is checked before the payload
is copied out of Zenoh, the element count when it is decoded. Samples waiting for the writer are bounded in
number (``queue_size``) and in bytes (``max_pending_bytes``). A sample beyond any bound is dropped and
counted per key and reason (``dropped_by_key``: ``over_budget`` / ``queue_full``); the counts go into the
``closed`` metadata record and the log. Exchanges are never dropped (each is one request the orchestrator
waited for).
"""

from __future__ import annotations

import json
import logging
import queue
import re
import threading
import time
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType, Writer

from common.codec import Message, decode, registered_types
from common.errors import ObjscanError, RemoteError, ServiceUnavailable
from common.log import event
from common.messages import Error, JointState
from common.runtime import COMMAND_BUDGET, Budget
from common.version import objscan_version
from services.recording import visual
from services.recording.errors import RecordingError

log = logging.getLogger("objscan.recording")

RAW_ENCODING = "msgpack"
PROTOBUF = "protobuf"
LIBRARY = "objscan-recorder"
RECORDING_NAME = "session.mcap"
_PART = re.compile(r"^session\.part(\d+)\.mcap$")
Requester = Callable[..., Awaitable[Message]]


def request_topic(key: str) -> str:
    return f"{key}?request"


def reply_topic(key: str) -> str:
    return f"{key}?reply"


def recording_parts(session_dir: str | Path) -> list[Path]:
    """The recording files of a session in the order they were written: session.mcap, session.part1.mcap, ..."""
    d = Path(session_dir)
    parts = sorted((int(m.group(1)), p) for p in d.glob("session.part*.mcap") if (m := _PART.match(p.name)))
    first = [d / RECORDING_NAME] if (d / RECORDING_NAME).is_file() else []
    return first + [p for _, p in parts]


def recording_path(session_dir: str | Path) -> Path:
    """Where the next recording of ``session_dir`` goes: ``session.mcap``, or ``session.partN.mcap`` when a
    (resumed) session already has recordings, so an earlier file is never reopened or overwritten."""
    d = Path(session_dir)
    existing = recording_parts(d)
    if not existing:
        return d / RECORDING_NAME
    last = max([int(m.group(1)) for p in existing if (m := _PART.match(p.name))] or [0])
    return d / f"session.part{last + 1}.mcap"


def schema_versions() -> dict[str, int]:
    """Wire type name → schema version, as this build encodes them (``v`` in every payload)."""
    return {name: int(cls.VERSION) for name, cls in sorted(registered_types().items())}


def _mcap_metadata(data: dict[str, Any]) -> dict[str, str]:
    """MCAP metadata maps are string → string: strings stay, anything else is JSON."""
    return {str(k): v if isinstance(v, str) else json.dumps(v, default=str) for k, v in data.items()}


#: Budgets of the streams an acquisition records, by the end of their key (any robot): a joint state is
#: command-sized (a few kB); a status update carries progress and figures, never bulk data.
STREAM_BUDGETS: dict[str, Budget] = {
    "/arm/state": COMMAND_BUDGET,
    "/orchestrator/status": Budget(max_bytes=1024 * 1024, max_elements=1 << 16),
}


def stream_budget(key: str, default: Budget) -> Budget:
    """The budget of a recorded stream's samples: ``STREAM_BUDGETS`` by key ending, else ``default``."""
    return next((b for end, b in STREAM_BUDGETS.items() if key.endswith(end)), default)


def _ns(t: float) -> int:
    return max(0, int(round(float(t) * 1e9)))


@dataclass
class RecorderConfig:
    """How a recording is written. Defaults suit a 12-view acquisition on one machine."""

    flush_interval_s: float = 1.0  # stream samples reach the disk at least this often
    flush_every_exchange: bool = True  # every request/reply is on disk before the next step
    chunk_size: int = 4 * 1024 * 1024
    compression: str = "lz4"  # "lz4" (needs the lz4 package), "zstd" (zstandard) or "none"
    visual: bool = True  # Foxglove channels (needs foxglove-sdk; skipped with a note if absent)
    state_visual_rate_hz: float = 10.0  # /tf and /arm/joints from the 50 Hz joint state, thinned
    queue_size: int = 20000  # pending items; beyond it stream samples are dropped (counted), never exchanges
    max_pending_bytes: int = 32 * 1024 * 1024  # stream sample bytes waiting for the writer; beyond: dropped
    sample_budget: Budget = Budget(max_bytes=1024 * 1024, max_elements=1 << 16)  # a key without its own budget


def _compression(name: str) -> CompressionType:
    name = name.lower()
    if name == "none":
        return CompressionType.NONE
    try:
        if name == "lz4":
            import lz4.frame  # noqa: F401

            return CompressionType.LZ4
        if name == "zstd":
            import zstandard  # noqa: F401

            return CompressionType.ZSTD
    except ImportError:
        event(log, f"{name} not installed; recording uncompressed", logging.WARNING)
        return CompressionType.NONE
    raise RecordingError(f"unknown compression {name!r}; use lz4, zstd or none")


class SessionRecorder:
    """Writes one MCAP recording; thread-safe producers (``tap``, ``record_sample``), one writer thread.

    ``counts`` (topic → messages written) is what a reader must find in the file after ``close()``.
    """

    def __init__(self, path: str | Path, metadata: dict[str, dict[str, Any]] | None = None,
                 config: RecorderConfig | None = None):
        self.path = Path(path)
        self.config = config or RecorderConfig()
        if self.path.exists():
            raise RecordingError(f"{self.path} exists; a recording is never overwritten "
                                 "(use recording_path() for the next part)", detail={"path": str(self.path)})
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "xb")  # noqa: SIM115 - owned by the writer thread, closed in close()
        self._writer = Writer(self._file, chunk_size=self.config.chunk_size,
                              compression=_compression(self.config.compression))
        self._writer.start(profile="", library=LIBRARY)
        self.visual = self.config.visual and visual.available()
        self.counts: dict[str, int] = {}
        self.dropped = 0  # stream samples not recorded, all keys and reasons
        self.dropped_by_key: dict[str, dict[str, int]] = {}  # key -> {"over_budget": n, "queue_full": n}
        self._budgets: dict[str, Budget] = {}
        self._pending_bytes = 0  # bytes of stream samples queued and not yet written
        self._pending_lock = threading.Lock()
        self.errors: list[str] = []
        self.io_error: OSError | None = None  # the first write failure (disk full): the recording ended there
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._sequence = 0
        self._last_state_visual = 0.0
        self._subscriptions: list[Any] = []
        self._queue: queue.Queue[tuple[Any, ...]] = queue.Queue(maxsize=self.config.queue_size)
        self._closed = False
        self._lock = threading.Lock()
        base = {"objscan": {"version": objscan_version(), "schema_versions": schema_versions()},
                "recording": {"raw_encoding": RAW_ENCODING, "request_topic": "KEY?request",
                              "reply_topic": "KEY?reply", "stream_topic": "KEY",
                              "times": "publish_time = sent / source stamp, log_time = received (ns since epoch)",
                              "visual": "foxglove protobuf" if self.visual
                              else "unavailable (pip install foxglove-sdk)",
                              "started": time.time()}}
        for name, data in {**base, **(metadata or {})}.items():
            self._writer.add_metadata(name, _mcap_metadata(data))
        self._writer.flush()
        self._thread = threading.Thread(target=self._run, name="session-recorder", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------------------ producers
    def tap(self, key: str, request: Message | None, reply: Message, t_sent: float, t_received: float) -> None:
        """Record one request and its reply (the ``Cell.tap`` signature). Never blocks for long.

        Raises ``RecordingError`` (code ``recording_failed``) once the file could not be written: a session
        that is recorded must not go on unrecorded without saying so."""
        if self.io_error is not None:
            raise RecordingError(f"the session recording {self.path.name} could not be written: {self.io_error}",
                                 code="recording_failed", detail={"path": str(self.path)})
        if not self._closed:
            self._queue.put(("exchange", key, request, reply, t_sent, t_received))

    def wrap(self, send: Requester) -> Requester:
        """A requester that records every exchange of ``send``, failures included, then behaves like it.

        ``Cell.tap`` sees only successful replies; a replay must also know which moves the arm refused,
        so the orchestrator's Cell is given this wrapper instead. A refused request is recorded with an
        ``Error`` reply (the remote code, message and detail); no reply at all (service unavailable,
        timeout) is recorded as an ``Error`` with ``detail.local = true``.
        """

        async def send_recorded(key: str, msg: Message | None = None, **kwargs: Any) -> Message:
            t0 = time.time()
            try:
                reply = await send(key, msg, **kwargs)
            except RemoteError as exc:
                detail = {k: v for k, v in exc.detail.items() if k != "key"}
                self.tap(key, msg, Error(code=exc.code, message=exc.message, detail=detail), t0, time.time())
                raise
            except ServiceUnavailable as exc:
                self.tap(key, msg, Error(code=exc.code, message=exc.message, detail={"local": True}), t0, time.time())
                raise
            self.tap(key, msg, reply, t0, time.time())
            return reply

        return send_recorded

    def record_sample(self, key: str, payload: bytes, t_received: float | None = None) -> None:
        """Record one stream sample's exact payload (called from a Zenoh callback thread), within its key's
        budget and the queue's bounds; otherwise it is dropped and counted."""
        if self._closed:
            return
        if self._admit(key, len(payload), self._budget(key)):
            self._enqueue_sample(key, bytes(payload), time.time() if t_received is None else t_received)

    def _budget(self, key: str) -> Budget:
        budget = self._budgets.get(key)
        return budget if budget is not None else stream_budget(key, self.config.sample_budget)

    def _admit(self, key: str, size: int, budget: Budget) -> bool:
        """Whether a sample of ``size`` bytes on ``key`` fits ``budget`` and the pending bytes (reserved if so)."""
        if size > budget.max_bytes:
            self._drop(key, "over_budget", size)
            return False
        with self._pending_lock:
            if self._pending_bytes + size > self.config.max_pending_bytes:
                full = True
            else:
                full = False
                self._pending_bytes += size
        if full:
            self._drop(key, "queue_full", size)
        return not full

    def _enqueue_sample(self, key: str, payload: bytes, t_received: float) -> None:
        try:
            self._queue.put_nowait(("sample", key, payload, t_received))
        except queue.Full:
            self._release(len(payload))
            self._drop(key, "queue_full", len(payload))

    def _release(self, size: int) -> None:
        with self._pending_lock:
            self._pending_bytes -= size

    def _drop(self, key: str, reason: str, size: int) -> None:
        """Count a dropped sample; the first of each key and reason is logged (the rest are in the counts)."""
        with self._pending_lock:
            self.dropped += 1
            per_key = self.dropped_by_key.setdefault(key, {})
            first = reason not in per_key
            per_key[reason] = per_key.get(reason, 0) + 1
        if first:
            event(log, "recording drops samples", logging.WARNING, key=key, reason=reason, bytes=size,
                  max_pending_bytes=self.config.max_pending_bytes)

    def pending_bytes(self) -> int:
        """Bytes of stream samples queued and not yet written (bounded by ``max_pending_bytes``)."""
        return self._pending_bytes

    def add_metadata(self, name: str, data: dict[str, Any]) -> None:
        if not self._closed:
            self._queue.put(("metadata", name, data))

    def subscribe(self, session: Any, keys: Iterable[str], budgets: dict[str, Budget] | None = None) -> None:
        """Record every sample published on ``keys`` (a Zenoh session; e.g. arm state and status streams).

        ``budgets``: key -> ``Budget`` (bytes and msgpack elements) a sample on that key may use; keys not
        named get their ``STREAM_BUDGETS`` entry, else ``config.sample_budget``. A sample over its budget is
        dropped before it is copied."""
        keys = list(keys)
        self._budgets.update(budgets or {})
        for key in keys:
            self._budgets.setdefault(key, self._budget(key))
        for key in keys:
            def on_sample(sample: Any, budget: Budget = self._budgets[key]) -> None:
                name = str(sample.key_expr)  # the sample's own key (the subscription's may be a wildcard)
                size = len(sample.payload)  # checked before the payload is copied out of Zenoh
                if not self._closed and self._admit(name, size, budget):
                    self._enqueue_sample(name, sample.payload.to_bytes(), time.time())

            self._subscriptions.append(session.declare_subscriber(key, on_sample))

    def close(self, summary: dict[str, Any] | None = None) -> dict[str, int]:
        """Stop subscribing, write what is queued, the ``closed`` metadata and the MCAP summary."""
        with self._lock:
            if self._closed:
                return dict(self.counts)
            for sub in self._subscriptions:
                try:
                    sub.undeclare()
                except Exception:  # the session may be gone already
                    pass
            self._subscriptions.clear()
            self._queue.put(("stop", summary or {}))
            self._closed = True
        self._thread.join(timeout=120)
        return dict(self.counts)

    def __enter__(self) -> SessionRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------------------ writer thread
    def _run(self) -> None:
        last_flush = time.monotonic()
        dirty = False
        while True:
            timeout = max(0.01, self.config.flush_interval_s - (time.monotonic() - last_flush))
            try:
                item = self._queue.get(timeout=timeout)
            except queue.Empty:
                item = None
            if self.io_error is not None:  # the file is broken: drain the queue, keep nothing
                if item is not None and item[0] == "sample":
                    self._release(len(item[2]))
                if item is not None and item[0] == "stop":
                    self._file.close()
                    return
                continue
            try:
                if item is None:
                    pass
                elif item[0] == "stop":
                    try:
                        self._finish(item[1])
                    except OSError as exc:
                        self.io_error = exc
                        self.errors.append(repr(exc))
                        event(log, "recording could not be closed", logging.ERROR, error=repr(exc))
                    return
                elif item[0] == "exchange":
                    self._write_exchange(*item[1:])
                    dirty = True
                    if self.config.flush_every_exchange:
                        self._writer.flush()
                        last_flush, dirty = time.monotonic(), False
                elif item[0] == "sample":
                    try:
                        self._write_sample(*item[1:])
                    finally:
                        self._release(len(item[2]))
                    dirty = True
                elif item[0] == "metadata":
                    self._writer.add_metadata(item[1], _mcap_metadata(item[2]))
                    dirty = True
                if dirty and time.monotonic() - last_flush >= self.config.flush_interval_s:
                    self._writer.flush()
                    last_flush, dirty = time.monotonic(), False
            except OSError as exc:  # disk full, file gone: the recording ends here, and says so (tap raises)
                self.io_error = exc
                self.errors.append(repr(exc))
                event(log, "recording write failed; recording stopped", logging.ERROR, error=repr(exc))
            except Exception as exc:  # a bad item must not end the recording
                self.errors.append(repr(exc))
                event(log, "recording item failed", logging.ERROR, error=repr(exc))

    def _finish(self, summary: dict[str, Any]) -> None:
        try:
            with self._pending_lock:
                dropped = {k: dict(v) for k, v in self.dropped_by_key.items()}
            if dropped:
                event(log, "recording closed with dropped samples", logging.WARNING, path=str(self.path),
                      dropped=self.dropped, by_key=dropped)
            self._writer.add_metadata("closed", _mcap_metadata({
                "counts": self.counts, "dropped_samples": self.dropped, "dropped_by_key": dropped,
                "budgets": {k: {"max_bytes": b.max_bytes, "max_elements": b.max_elements}
                            for k, b in self._budgets.items()},
                "max_pending_bytes": self.config.max_pending_bytes, "queue_size": self.config.queue_size,
                "errors": self.errors[:20], "ended": time.time(), **summary}))
            self._writer.finish()
        finally:
            self._file.close()

    def _channel(self, topic: str, encoding: str, schema_name: str | None, metadata: dict[str, str]) -> int:
        cid = self._channels.get(topic)
        if cid is None:
            sid = 0
            if schema_name is not None:
                sid = self._schemas.get(schema_name, 0)
                if not sid:
                    enc, data = visual.schema(schema_name)
                    sid = self._writer.register_schema(name=schema_name, encoding=enc, data=data)
                    self._schemas[schema_name] = sid
            cid = self._writer.register_channel(topic=topic, message_encoding=encoding, schema_id=sid,
                                                metadata=metadata)
            self._channels[topic] = cid
        return cid

    def _add(self, cid: int, topic: str, data: bytes, log_time: float, publish_time: float, sequence: int) -> None:
        self._writer.add_message(channel_id=cid, log_time=_ns(log_time), publish_time=_ns(publish_time),
                                 sequence=sequence & 0xFFFFFFFF, data=data)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def _raw_channel(self, key: str, kind: str, topic: str) -> int:
        return self._channel(topic, RAW_ENCODING, None, {"zenoh_key": key, "kind": kind})

    def _write_exchange(self, key: str, request: Message | None, reply: Message, t_sent: float,
                        t_received: float) -> None:
        self._sequence += 1
        seq = self._sequence
        req_bytes = request.encode() if request is not None else b""
        t_req, t_rep = request_topic(key), reply_topic(key)
        self._add(self._raw_channel(key, "request", t_req), t_req, req_bytes, t_sent, t_sent, seq)
        self._add(self._raw_channel(key, "reply", t_rep), t_rep, reply.encode(), t_received, t_sent, seq)
        if self.visual and not isinstance(reply, Error):
            self._write_visual(visual.for_exchange(t_received, key, request, reply), t_received, seq)

    def _write_sample(self, key: str, payload: bytes, t_received: float) -> None:
        msg: Message | None
        budget = self._budget(key)
        try:
            msg = decode(payload, max_bytes=budget.max_bytes, max_elements=budget.max_elements)
        except ObjscanError:
            msg = None  # recorded as it came; a reader will find out
        stamp = float(getattr(msg, "stamp", 0.0) or 0.0) or t_received
        self._add(self._raw_channel(key, "sample", key), key, payload, t_received, stamp, self.counts.get(key, 0))
        due = t_received - self._last_state_visual >= 1.0 / self.config.state_visual_rate_hz
        if self.visual and isinstance(msg, JointState) and due:
            self._last_state_visual = t_received
            self._write_visual(visual.for_sample(stamp, msg), t_received, self.counts[key])

    def _write_visual(self, items: list[visual.Visual], t: float, seq: int) -> None:
        for topic, schema_name, data in items:
            cid = self._channel(topic, PROTOBUF, schema_name, {"derived": "true"})
            self._add(cid, topic, data, t, t, seq)
