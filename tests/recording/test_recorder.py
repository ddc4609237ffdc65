"""SessionRecorder, reader and recover on synthetic messages (no services): fast."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from common.api import CaptureRequest, MoveRequest, MoveResult
from common.codec import decode
from common.errors import RemoteError, ServiceUnavailable
from common.messages import Error, Intrinsics, JointState, Ok, RGBDFrame
from services.recording import visual
from services.recording.errors import RecordingError
from services.recording.reader import read_recording, recover
from services.recording.recorder import SessionRecorder, recording_parts, recording_path, schema_versions

MOVE = "objscan/robot0/arm/move"
CAPTURE = "objscan/robot0/camera/capture"
STATE = "objscan/robot0/arm/state"


def _pose(x: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = [x, 0.0, 0.3]
    return T


def _frame(seed: int = 0) -> RGBDFrame:
    rng = np.random.default_rng(seed)
    return RGBDFrame(color=rng.integers(0, 255, (48, 64, 3), dtype=np.uint8),
                     depth=rng.integers(300, 900, (48, 64), dtype=np.uint16),
                     intrinsics=Intrinsics(width=64, height=48, fx=50.0, fy=50.0, cx=32.0, cy=24.0),
                     T_base_camera=_pose(0.2), stamp=12.5, seq=seed)


def _state(t: float) -> JointState:
    return JointState(names=[f"j{i}" for i in range(6)], position=np.linspace(0, 0.5, 6), stamp=t,
                      T_base_gripper=_pose(0.3), T_base_camera=_pose(0.35))


def _write_sample_session(path: Path) -> tuple[SessionRecorder, list[tuple]]:
    rec = SessionRecorder(path, {"session": {"object": "milk", "seed": 7, "config": {"views": 3}}})
    sent = []
    t = 1_700_000_000.0
    for i in range(4):
        req = MoveRequest(kind="pose", target=_pose(0.1 * i), frame="camera")
        rep = MoveResult(q=np.full(6, 0.1 * i), T_base_gripper=_pose(0.1 * i), T_base_camera=_pose(0.1 * i + 0.05))
        rec.tap(MOVE, req, rep, t + i, t + i + 0.5)
        sent.append((MOVE, req, rep, t + i, t + i + 0.5))
    req, rep = CaptureRequest(width=64, height=48), _frame(1)
    rec.tap(CAPTURE, req, rep, t + 10, t + 10.2)
    sent.append((CAPTURE, req, rep, t + 10, t + 10.2))
    err = Error(code="line_unreachable", message="straight line leaves the workspace")
    rec.tap(MOVE, MoveRequest(kind="linear", target=_pose(0.9)), err, t + 11, t + 11.1)
    sent.append((MOVE, MoveRequest(kind="linear", target=_pose(0.9)), err, t + 11, t + 11.1))
    for k in range(30):
        rec.record_sample(STATE, _state(t + 20 + k * 0.02).encode(), t + 20 + k * 0.02)
    return rec, sent


def test_every_channel_and_message_reads_back_with_the_mcap_library(tmp_path):
    path = tmp_path / "session.mcap"
    rec, sent = _write_sample_session(path)
    counts = rec.close()
    assert counts[f"{MOVE}?request"] == 5 and counts[f"{MOVE}?reply"] == 5
    assert counts[STATE] == 30
    with open(path, "rb") as f:
        reader = make_reader(f)
        got: dict[str, int] = {}
        for _schema, channel, _msg in reader.iter_messages():
            got[channel.topic] = got.get(channel.topic, 0) + 1
        summary = reader.get_summary()
    assert got == counts
    assert summary.statistics.message_count == sum(counts.values())
    assert {c.topic for c in summary.channels.values()} == set(counts)


def test_raw_payloads_times_and_pairing_are_exact(tmp_path):
    path = tmp_path / "session.mcap"
    rec, sent = _write_sample_session(path)
    rec.close()
    back = read_recording(path)
    assert not back.truncated
    assert len(back.exchanges) == len(sent)
    for ex, (key, req, rep, t0, t1) in zip(back.exchanges, sent, strict=True):
        assert ex.key == key
        assert ex.request == req.encode() and ex.reply == rep.encode()  # the exact codec payloads
        assert ex.t_sent == pytest.approx(t0, abs=1e-6) and ex.t_received == pytest.approx(t1, abs=1e-6)
    assert isinstance(back.exchanges[-1].reply_message(), Error)
    assert back.channels[f"{MOVE}?request"]["encoding"] == "msgpack"
    assert back.channels[f"{MOVE}?request"]["metadata"] == {"zenoh_key": MOVE, "kind": "request"}
    samples = back.samples[STATE]
    assert len(samples) == 30 and isinstance(decode(samples[0][1]), JointState)
    assert back.metadata["session"]["seed"] == 7 and back.metadata["session"]["config"] == {"views": 3}
    assert back.metadata["objscan"]["schema_versions"] == schema_versions()
    assert back.metadata["closed"]["counts"] == back.counts


@pytest.mark.skipif(not visual.available(), reason="foxglove-sdk not installed (visual channels off)")
def test_foxglove_channels_carry_the_images_transforms_and_schemas(tmp_path):
    path = tmp_path / "session.mcap"
    rec, _ = _write_sample_session(path)
    rec.close()
    frame = _frame(1)
    with open(path, "rb") as f:
        reader = make_reader(f)
        by_topic: dict[str, list] = {}
        for schema, channel, msg in reader.iter_messages(topics=["/camera/depth", "/camera/color", "/tf"]):
            by_topic.setdefault(channel.topic, []).append((schema, channel, msg))
    schema, channel, msg = by_topic["/camera/depth"][0]
    assert (schema.name, schema.encoding, channel.message_encoding) == ("foxglove.RawImage", "protobuf", "protobuf")
    assert frame.depth.astype("<u2").tobytes() in msg.data  # the depth image travels unaltered
    jpeg = by_topic["/camera/color"][0][2].data
    assert b"\xff\xd8\xff" in jpeg  # a JPEG stream inside the CompressedImage
    # /tf from 4 moves + the 30 joint states thinned to 10 Hz over 0.6 s
    assert len(by_topic["/tf"]) >= 4 + 5
    assert by_topic["/tf"][0][0].name == "foxglove.FrameTransforms"


def test_parts_never_overwrite_an_earlier_recording(tmp_path):
    assert recording_path(tmp_path) == tmp_path / "session.mcap"
    SessionRecorder(recording_path(tmp_path)).close()
    assert recording_path(tmp_path) == tmp_path / "session.part1.mcap"
    SessionRecorder(recording_path(tmp_path)).close()
    assert recording_path(tmp_path) == tmp_path / "session.part2.mcap"
    assert recording_parts(tmp_path) == [tmp_path / "session.mcap", tmp_path / "session.part1.mcap"]
    with pytest.raises(RecordingError):
        SessionRecorder(tmp_path / "session.mcap")


def test_wrapped_requester_records_refusals_and_silence_then_reraises(tmp_path):
    rec = SessionRecorder(tmp_path / "session.mcap")

    async def send(key, msg=None, *, timeout):  # noqa: ANN001, ANN202
        if key.endswith("move"):
            raise RemoteError("joint limit", code="unreachable", detail={"key": key, "joint": 3})
        if key.endswith("world"):
            raise ServiceUnavailable(f"no service answers {key}")
        return Ok(info={"fine": True})

    wrapped = rec.wrap(send)

    async def scenario() -> None:
        with pytest.raises(RemoteError):
            await wrapped(MOVE, MoveRequest(kind="home"), timeout=1.0)
        with pytest.raises(ServiceUnavailable):
            await wrapped("objscan/robot0/sim/world", None, timeout=1.0)
        assert (await wrapped("objscan/robot0/arm/scene", None, timeout=1.0)).info == {"fine": True}

    asyncio.run(scenario())
    rec.close()
    ex = read_recording(tmp_path / "session.mcap").exchanges
    assert [e.key.rsplit("/", 1)[1] for e in ex] == ["move", "world", "scene"]
    refused = ex[0].reply_message()
    assert isinstance(refused, Error) and refused.code == "unreachable" and refused.detail == {"joint": 3}
    silent = ex[1].reply_message()
    assert silent.code == "unavailable" and silent.detail == {"local": True}
    assert ex[1].request == b""  # a request without a message is recorded as an empty payload


def test_a_killed_recorder_leaves_a_readable_file_up_to_the_last_flush(tmp_path):
    """The writer is SIGKILLed mid-session: every flushed exchange reads back; recover() completes the file."""
    path = tmp_path / "session.mcap"
    script = textwrap.dedent(f"""
        import os, signal, time, sys
        import numpy as np
        sys.path.insert(0, {str(Path(__file__).resolve().parents[2])!r})
        from common.api import MoveRequest, MoveResult
        from services.recording.recorder import SessionRecorder, RecorderConfig
        rec = SessionRecorder({str(path)!r}, config=RecorderConfig(flush_interval_s=0.05))
        T = np.eye(4)
        for i in range(25):
            rec.tap("objscan/robot0/arm/move", MoveRequest(kind="pose", target=T),
                    MoveResult(q=np.full(6, float(i)), T_base_gripper=T, T_base_camera=T), time.time(), time.time())
        while rec._queue.qsize():   # everything handed to the writer thread
            time.sleep(0.01)
        time.sleep(0.3)             # past the flush of the last exchange
        print("flushed", flush=True)
        rec.tap("objscan/robot0/arm/move", None, MoveResult(q=np.zeros(6), T_base_gripper=T, T_base_camera=T),
                time.time(), time.time())
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    assert "flushed" in proc.stdout
    back = read_recording(path)
    assert back.truncated == [path]  # no footer: the process never closed it
    qs = [decode(e.reply).q[0] for e in back.exchanges]
    assert qs[:25] == [float(i) for i in range(25)]  # nothing flushed is lost, in order
    with open(path, "rb") as f, pytest.raises(Exception):  # noqa: B017 - the plain seeking reader gives up
        list(make_reader(f).iter_messages())
    fixed = tmp_path / "recovered.mcap"
    info = recover(path, fixed)
    assert info["source_truncated"] and info["messages"] == sum(back.counts.values())
    with open(fixed, "rb") as f:
        reader = make_reader(f)
        assert sum(1 for _ in reader.iter_messages()) == info["messages"]
        assert reader.get_summary().statistics.message_count == info["messages"]


def test_not_a_recording_is_a_typed_error(tmp_path):
    bad = tmp_path / "x.mcap"
    bad.write_bytes(b"definitely not mcap")
    with pytest.raises(RecordingError):
        read_recording(bad)
    with pytest.raises(RecordingError):
        read_recording(tmp_path / "missing.mcap")
    with pytest.raises(RecordingError):
        read_recording(tmp_path)  # a folder without session.mcap


def test_recorder_does_not_block_the_caller(tmp_path):
    """tap() only enqueues: 20 full 640x480 frames are handed over far faster than they are written."""
    rec = SessionRecorder(tmp_path / "session.mcap")
    frame = RGBDFrame(color=np.zeros((480, 640, 3), np.uint8), depth=np.full((480, 640), 700, np.uint16),
                      intrinsics=Intrinsics(width=640, height=480, fx=600.0, fy=600.0, cx=320.0, cy=240.0),
                      T_base_camera=np.eye(4))
    t0 = time.perf_counter()
    for _ in range(20):
        rec.tap(CAPTURE, CaptureRequest(width=640, height=480), frame, time.time(), time.time())
    handed_over = time.perf_counter() - t0
    rec.close()
    assert handed_over < 0.05
    assert read_recording(tmp_path / "session.mcap").counts[f"{CAPTURE}?reply"] == 20


def test_close_writes_everything_queued_before_it(tmp_path):
    """close() right after a burst of samples: all 200 are written; a sample after close is ignored."""
    rec = SessionRecorder(tmp_path / "session.mcap")
    for k in range(200):
        rec.record_sample(STATE, _state(float(k)).encode(), float(k))
    counts = rec.close()
    rec.record_sample(STATE, _state(999.0).encode())  # after close: ignored, not an error
    assert counts[STATE] == 200
    assert read_recording(tmp_path / "session.mcap").counts[STATE] == 200


def test_recorded_acquisition_wraps_the_cell_and_cleans_up_when_it_cannot_start(tmp_path):
    from services.orchestrator.journal import Journal
    from services.orchestrator.recording_hook import recorded_acquisition

    class FakeAcquisition:
        def __init__(self, cell):  # noqa: ANN001
            self.cell, self.resumed, self.j = cell, False, Journal(config={}, status="done")
            self.store = type("S", (), {"path": tmp_path})()
            self.config = type("C", (), {"to_dict": lambda self: {"object": "milk", "seed": 2}})()

        async def run(self) -> dict:
            await self.cell._send(MOVE, MoveRequest(kind="home"), timeout=1.0)
            return {"status": "done"}

    async def send(key, msg=None, *, timeout):  # noqa: ANN001, ANN202
        return _moved_result()

    acq, run = recorded_acquisition(FakeAcquisition, send, tmp_path, None, "robot0")
    asyncio.run(run)
    rec = read_recording(tmp_path / "session.mcap")
    assert [e.key for e in rec.exchanges] == [MOVE] and rec.metadata["session"]["seed"] == 2
    assert rec.metadata["closed"]["status"] == "done"

    def broken(cell):  # noqa: ANN001, ANN202
        raise ValueError("bad journal")

    with pytest.raises(ValueError):
        recorded_acquisition(broken, send, tmp_path, None, "robot0")
    assert recording_parts(tmp_path) == [tmp_path / "session.mcap"]  # no empty session.part1.mcap left


def _moved_result() -> MoveResult:
    return MoveResult(q=np.zeros(6), T_base_gripper=np.eye(4), T_base_camera=np.eye(4))


def test_info_and_recover_command(tmp_path, capsys):
    from services.recording.__main__ import main

    rec, _ = _write_sample_session(tmp_path / "session.mcap")
    rec.close()
    assert main(["info", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "object=milk" in out and f"{MOVE}?request" in out and "closed cleanly: True" in out
    assert main(["recover", str(tmp_path / "session.mcap"), str(tmp_path / "copy.mcap")]) == 0
    assert read_recording(tmp_path / "copy.mcap").counts == read_recording(tmp_path / "session.mcap").counts
    assert main(["info", str(tmp_path / "nothing.mcap")]) == 2
