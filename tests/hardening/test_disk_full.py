"""A full disk ends the session ``failed`` with the reason on disk; nothing is swallowed.

Why: the failure path itself raised (``OSError`` from writing the journal), so the journal stayed
``running``; the MCAP recorder logged write errors and went on as if recording; ``model.ply`` was renamed
from a fixed temporary name without fsync. The disk is a real one: a 4 MB tmpfs mounted for the test (root
needed; skipped with the reason otherwise)."""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import time
import uuid

import numpy as np
import pytest

from common.errors import ObjscanError, RemoteError
from common.messages import PointCloud, Request
from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.machine import Acquisition
from services.recording.recorder import SessionRecorder
from services.registration.cloud import read_ply, write_ply
from services.session_store import RESERVE, SessionStore
from tests.orchestrator.test_run_ends import RefusingCell


@pytest.fixture
def tiny_disk(tmp_path):
    mnt = tmp_path / "disk"
    mnt.mkdir()
    out = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4m", f"objscan-test-{uuid.uuid4().hex[:6]}",
                          str(mnt)], capture_output=True, text=True)
    if out.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here (needs root/CAP_SYS_ADMIN): {out.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def fill(disk) -> None:
    """Write filler files until the disk is full (unbuffered: nothing left to flush later)."""
    for name, block in (("filler", 65536), ("filler2", 512)):
        fd = os.open(disk / name, os.O_WRONLY | os.O_CREAT)
        try:
            while True:
                os.write(fd, b"\0" * block)
        except OSError:
            pass
        finally:
            os.close(fd)


def test_a_full_disk_ends_the_session_failed_with_the_reason_on_disk(tiny_disk):
    store = SessionStore.create(tiny_disk / "session")
    assert (tiny_disk / "session" / RESERVE).stat().st_size >= 1 << 20
    fill(tiny_disk)
    cell = RefusingCell(RemoteError("arm busy", code="busy"))
    published: list[dict] = []
    acq = Acquisition(cell, store, AcquisitionConfig(views=3), on_status=published.append)  # type: ignore[arg-type]
    status = asyncio.run(asyncio.wait_for(acq.run(), 30))  # before: OSError escaped run()
    assert status["status"] == "failed" and status["last_error"]["code"] == "disk_full"
    journal = json.loads((tiny_disk / "session" / "journal.json").read_text())
    assert journal["status"] == "failed" and journal["error"]["code"] == "disk_full"
    assert "No space left" in journal["error"]["message"]
    assert published[-1]["status"] == "failed"
    assert "move/home" in cell.asked  # parked all the same


def test_the_recorder_reports_a_full_disk(tiny_disk):
    rec = SessionRecorder(tiny_disk / "session.mcap")
    fill(tiny_disk)
    big = Request(params={"blob": np.random.default_rng(0).integers(0, 255, 300_000, dtype=np.uint8)})
    with pytest.raises(ObjscanError) as err:
        for _ in range(200):
            rec.tap("objscan/robot0/camera/capture", big, big, time.time(), time.time())
            time.sleep(0.02)
    assert err.value.code == "recording_failed"
    t0 = time.perf_counter()
    rec.close({"status": "failed"})
    assert time.perf_counter() - t0 < 10
    assert rec.io_error is not None


def test_a_model_written_on_a_full_disk_raises_and_keeps_the_old_one(tiny_disk):
    old = PointCloud(xyz=np.zeros((100, 3), np.float32))
    write_ply(tiny_disk / "model.ply", old)
    fill(tiny_disk)
    new = PointCloud(xyz=np.ones((200_000, 3), np.float32))
    with pytest.raises(ObjscanError):
        write_ply(tiny_disk / "model.ply", new)
    assert len(read_ply(tiny_disk / "model.ply").xyz) == 100  # the old file, whole
    assert sorted(p.name for p in tiny_disk.iterdir() if p.name.startswith(".")) == []  # no temporary left
