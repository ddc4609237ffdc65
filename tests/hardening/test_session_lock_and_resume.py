"""Resume of a finished or failed session, and one orchestrator per session folder.

Why: resuming a ``done`` or ``failed`` session returned without publishing any status, so ``objscan scan
--resume`` waited forever (and the summary of a failed run tells users to resume it); two orchestrators could
work on one folder at once, and ``write_ply`` used one fixed temporary name, so two writers collided."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import threading

import numpy as np
import pytest

from common.messages import PointCloud
from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.machine import Acquisition
from services.registration.cloud import read_ply, write_ply
from services.session_store import SessionLocked, SessionStore
from tests.orchestrator.test_run_ends import RefusingCell


def _journal(path, **fields):
    store = SessionStore(path)
    acq = Acquisition(RefusingCell(RuntimeError("unused")), store, AcquisitionConfig(views=3))  # type: ignore[arg-type]
    acq.j.update(**fields)
    store.save_journal(acq.j.to_dict())
    return store


def test_resuming_a_finished_session_publishes_its_final_status(tmp_path):
    store = _journal(tmp_path, state="done", status="done", model_path=str(tmp_path / "model.ply"))
    published: list[dict] = []
    cell = RefusingCell(RuntimeError("the cell must not be used"))
    acq = Acquisition(cell, store, AcquisitionConfig(), on_status=published.append)  # type: ignore[arg-type]
    status = asyncio.run(asyncio.wait_for(acq.run(), 10))
    assert status["status"] == "done" and published and published[-1]["status"] == "done"
    assert cell.asked == []  # nothing moved


def test_resuming_a_failed_session_retries_where_it_failed(tmp_path):
    store = _journal(tmp_path, state="failed", status="failed", view=1, rescans={"1": 2},
                     error={"code": "acquisition_failed", "message": "view 1: giving up", "state": "register"})
    published: list[dict] = []
    cell = RefusingCell(RuntimeError("arm unplugged"))
    acq = Acquisition(cell, store, AcquisitionConfig(), on_status=published.append)  # type: ignore[arg-type]
    asyncio.run(asyncio.wait_for(acq.run(), 30))
    journal = json.loads((tmp_path / "journal.json").read_text())
    retry = [d for d in journal["decisions"] if d["what"] == "resumed after failure"]
    assert retry and retry[0]["state"] == "register" and retry[0]["previous"] == "acquisition_failed"
    assert "gripper" in cell.asked  # it really ran again (and failed again, this cell refuses everything)
    assert any(p["status"] == "running" for p in published) and published[-1]["status"] == "failed"
    assert journal["previous_errors"][0]["code"] == "acquisition_failed"


def test_a_session_folder_has_one_orchestrator(tmp_path):
    first = SessionStore(tmp_path).acquire_lock()
    with pytest.raises(SessionLocked) as err:
        SessionStore(tmp_path).acquire_lock()
    assert err.value.code == "session_locked"
    # another process taking the same lock file (plain flock: the process need not import objscan)
    probe = ("import fcntl, os, sys\nfd = os.open(os.path.join(sys.argv[1], '.session.lock'), os.O_RDWR)\n"
             "try:\n    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB); print('got')\n"
             "except BlockingIOError:\n    print('locked')")
    out = subprocess.run([sys.executable, "-c", probe, str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "locked", out.stderr
    first.release_lock()
    out = subprocess.run([sys.executable, "-c", probe, str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "got", out.stderr


def test_a_killed_holder_leaves_no_stale_lock(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", "import fcntl, os, sys, time\n"
                               "fd = os.open(os.path.join(sys.argv[1], '.session.lock'), os.O_RDWR | os.O_CREAT)\n"
                               "fcntl.flock(fd, fcntl.LOCK_EX); print('held', flush=True); time.sleep(60)",
                               str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(SessionLocked):
            SessionStore(tmp_path).acquire_lock()
    finally:
        holder.kill()
        holder.wait()
    SessionStore(tmp_path).acquire_lock().release_lock()


def test_concurrent_writers_of_one_file_never_collide(tmp_path):
    """Two writers of model.ply at once: every write lands whole (unique temporary names)."""
    errors: list[BaseException] = []
    clouds = [PointCloud(xyz=np.full((2000, 3), float(i), np.float32)) for i in range(2)]

    def writer(i: int) -> None:
        try:
            for _ in range(15):
                write_ply(tmp_path / "model.ply", clouds[i])
        except BaseException as exc:  # noqa: BLE001 - collected for the assertion
            errors.append(exc)

    threads = [threading.Thread(target=writer, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    xyz = read_ply(tmp_path / "model.ply").xyz
    assert len(xyz) == 2000 and np.ptp(xyz) == 0.0  # one writer's cloud, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.ply"]  # no temporary left behind

