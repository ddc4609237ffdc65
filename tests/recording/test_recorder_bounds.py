"""The recorder's subscriptions are bounded: per-key budgets and a queue that drops and counts, never grows.

It used to copy every ``arm/state`` sample of any size (up to the transport's 512 MB) into a 20,000-item
queue: a flood of large samples while the writer is busy held them all in memory. Here the writer is held
up on purpose while samples flood in; what waits in the queue is measured from the queue itself.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from common import keys
from common.messages import JointState
from common.runtime import COMMAND_BUDGET
from services.recording.reader import read_recording
from services.recording.recorder import RecorderConfig, SessionRecorder

pytestmark = pytest.mark.timeout(180)
ROBOT = keys.DEFAULT_ROBOT
STATE = keys.arm(ROBOT, "state")
NAMES = [f"joint{i}" for i in range(1, 7)]


def _state(k: int, extra: int = 0) -> bytes:
    """A joint state; ``extra`` float64s of velocity make it as large as a hostile publisher likes."""
    velocity = np.zeros(extra) if extra else None
    return JointState(names=NAMES, position=np.full(6, 0.01 * k), velocity=velocity, stamp=1000.0 + k).encode()


def _queued_bytes(rec: SessionRecorder) -> int:
    """Bytes of stream samples waiting in the recorder's queue right now."""
    with rec._queue.mutex:
        return sum(len(item[2]) for item in rec._queue.queue if item[0] == "sample")


def _hold_writer(rec: SessionRecorder) -> threading.Event:
    """Make the writer thread wait before its first sample until the returned event is set."""
    release = threading.Event()
    write = rec._write_sample

    def held(*args):  # noqa: ANN002, ANN202
        release.wait(60)
        return write(*args)

    rec._write_sample = held
    return release


def test_a_flood_of_large_arm_state_samples_stays_bounded_and_is_counted(service_group, tmp_path):
    """Over Zenoh: 60 samples of 1 MB and 300 ordinary ones on ``arm/state`` while the writer is busy. The large
    ones are refused by the key's budget before they are copied (none waits in the queue), the ordinary ones
    are all recorded, and the drops reach the recording's ``closed`` metadata."""
    session = service_group.session
    rec = SessionRecorder(tmp_path / "session.mcap")
    release = _hold_writer(rec)
    rec.subscribe(session, [STATE])
    pub = session.declare_publisher(STATE)
    big, small = 60, 300
    peak = 0
    for k in range(small):
        pub.put(_state(k))
        if k % 5 == 0 and k // 5 < big:
            pub.put(_state(k, extra=128 * 1024))  # 1 MB
            peak = max(peak, _queued_bytes(rec))
    deadline = time.monotonic() + 60
    while rec._queue.qsize() + rec.dropped < big + small - 1 and time.monotonic() < deadline:
        peak = max(peak, _queued_bytes(rec))
        time.sleep(0.05)
    peak = max(peak, _queued_bytes(rec))
    assert peak <= small * 1024, f"{peak / 1e6:.1f} MB of samples waited in the queue"
    assert peak <= rec.config.max_pending_bytes
    release.set()
    time.sleep(0.5)
    rec.close()
    assert rec.dropped_by_key == {STATE: {"over_budget": big}}
    back = read_recording(tmp_path / "session.mcap")
    closed = back.metadata["closed"]
    assert closed["dropped_samples"] == big
    assert closed["dropped_by_key"] == {STATE: {"over_budget": big}}
    assert closed["budgets"][STATE]["max_bytes"] == COMMAND_BUDGET.max_bytes
    assert rec.counts[STATE] == small  # every ordinary state recorded, none lost to the flood
    pub.undeclare()


def test_the_queue_drops_and_counts_when_the_writer_falls_behind(tmp_path, caplog):
    """Samples within budget but faster than the writer: the pending bytes and items never pass their bounds,
    the excess is counted per key (``queue_full``) and logged once, and what was queued is written."""
    cfg = RecorderConfig(max_pending_bytes=256 * 1024, queue_size=500, visual=False)
    rec = SessionRecorder(tmp_path / "session.mcap", config=cfg)
    release = _hold_writer(rec)
    other = keys.orchestrator(ROBOT, "status")
    payload = _state(0, extra=4 * 1024)  # ~33 kB: within arm/state's 64 kB budget
    peak_bytes = peak_items = 0
    with caplog.at_level("WARNING", logger="objscan.recording"):
        for _ in range(200):
            rec.record_sample(STATE, payload)
            peak_bytes = max(peak_bytes, _queued_bytes(rec))
            peak_items = max(peak_items, rec._queue.qsize())
        for _ in range(2000):
            rec.record_sample(other, b"\x80")  # tiny: bounded by the item count
            peak_items = max(peak_items, rec._queue.qsize())
    assert peak_bytes <= cfg.max_pending_bytes and rec.pending_bytes() <= cfg.max_pending_bytes
    assert peak_items <= cfg.queue_size
    queued_state = 200 - rec.dropped_by_key[STATE]["queue_full"]
    assert queued_state == cfg.max_pending_bytes // len(payload)
    assert rec.dropped_by_key[other]["queue_full"] > 0
    assert sum(r.getMessage().count("recording drops samples") for r in caplog.records) == 2  # once per key
    release.set()
    rec.close()
    assert rec.pending_bytes() == 0
    assert rec.counts[STATE] == queued_state
    closed = read_recording(tmp_path / "session.mcap").metadata["closed"]
    assert closed["dropped_by_key"] == rec.dropped_by_key and closed["dropped_samples"] == rec.dropped
    assert closed["max_pending_bytes"] == cfg.max_pending_bytes


def test_a_sample_over_its_key_budget_is_not_copied(tmp_path):
    rec = SessionRecorder(tmp_path / "session.mcap", config=RecorderConfig(visual=False))
    rec.record_sample(STATE, b"\x00" * (COMMAND_BUDGET.max_bytes + 1))
    rec.record_sample(STATE, _state(1))
    rec.close()
    assert rec.dropped_by_key == {STATE: {"over_budget": 1}} and rec.counts[STATE] == 1
