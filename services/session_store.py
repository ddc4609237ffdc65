"""The session folder as the orchestrator's memory: every step's inputs and outputs, before the next step.

Besides the shared layout (``session.json``, ``view_KK/scan_J/...``, see ``common/session_folder.py``) it
keeps:

- ``journal.json``: the state machine's position (state, view, attempts, counters) and every decision
  with its timing, rewritten atomically after each step: a killed orchestrator resumes from it;
- ``view_KK/view.json`` + ``view_KK/object.ply``: the registered view (static result);
- ``view_KK/grasps.json``: the plan and what was tried;
- ``model.ply`` and ``report.json`` at the end;
- ``.reserve``: 1 MB of disk set aside when the session is created; on a full disk it is released so the
  journal can still record the failure and its reason;
- ``.session.lock``: held (``fcntl.flock``) by the one orchestrator working on the session, so two
  never write one folder.

``SessionStore.create`` makes a new session only in an absent or empty folder, ``SessionStore.open``
only opens a folder that holds a journal: a session never adopts (and a re-scan never moves things in) a
folder it did not create.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from common.api import ViewResult
from common.errors import ObjscanError
from common.messages import Plane, PointCloud, RGBDFrame
from common.session_folder import (
    MODEL_FILE,
    atomic_write_json,
    new_folder_refusal,
    read_scan,
    scan_complete,
    view_dir,
    write_scan,
    write_session,
)
from services.registration.api import read_ply, write_ply

JOURNAL = "journal.json"
LOCK = ".session.lock"
PRE_SESSION = frozenset({"logs"})  # what may be in a new session's folder: ``objscan scan``'s process logs
RESERVE = ".reserve"
RESERVE_BYTES = 1 << 20
_DISK_FULL = (errno.ENOSPC, errno.EDQUOT)


class SessionLocked(ObjscanError):
    """Another orchestrator (process) is working on this session folder."""

    code = "session_locked"


class NotASession(ObjscanError):
    """The folder is not one this store may use (not empty for a new session, no journal to resume)."""

    code = "not_a_session"


class SessionStore:
    """Reads and writes one acquisition's folder; all writes are atomic (``common.atomic``)."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.path.mkdir(parents=True, exist_ok=True)
        self._lock_fd: int | None = None

    @classmethod
    def create(cls, path: Path) -> SessionStore:
        """A new session in ``path``, which must be absent or an empty folder (checked before creating it);
        ``logs/`` alone is allowed: ``objscan scan`` starts the cell, logging there, before the session."""
        path = Path(path)
        refusal = new_folder_refusal(path, PRE_SESSION)
        if refusal is not None:
            what = "already holds a session; resume it or choose another folder" if (path / JOURNAL).is_file() \
                else refusal
            raise NotASession(f"{path} {what}", detail={"path": str(path)})
        store = cls(path)
        store.reserve_space()
        return store

    @classmethod
    def open(cls, path: Path) -> SessionStore:
        """An existing session (``path`` holds ``journal.json``), to resume it."""
        path = Path(path)
        if not (path / JOURNAL).is_file():
            raise NotASession(f"{path} has no {JOURNAL} to resume from", detail={"path": str(path)})
        store = cls(path)
        store.reserve_space()
        return store

    def reserve_space(self, nbytes: int = RESERVE_BYTES) -> bool:
        """Set ``nbytes`` of disk aside (really allocated) for the last journal write; False if the disk is
        already too full (then the failure journal may not fit: still tried)."""
        p = self.path / RESERVE
        if p.is_file() and p.stat().st_size >= nbytes:
            return True
        try:
            fd = os.open(p, os.O_WRONLY | os.O_CREAT, 0o644)
            try:
                os.posix_fallocate(fd, 0, nbytes)
                os.fsync(fd)
            finally:
                os.close(fd)
            return True
        except OSError:
            p.unlink(missing_ok=True)
            return False

    # ----------------------------------------------------------------------------------- lock
    def acquire_lock(self) -> SessionStore:
        """Take the session's lock for this process, or raise ``SessionLocked`` at once (never waits).

        ``flock`` locks belong to the open file: they exclude other processes *and* another store of the
        same folder in this process, and the kernel drops them when the holder dies (a killed orchestrator
        never leaves a stale lock).
        """
        if self._lock_fd is not None:
            return self
        fd = os.open(self.path / LOCK, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise SessionLocked(f"another orchestrator is working on {self.path}",
                                detail={"path": str(self.path)}) from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._lock_fd = fd
        return self

    def release_lock(self) -> None:
        if self._lock_fd is not None:
            fd, self._lock_fd = self._lock_fd, None
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)

    # ----------------------------------------------------------------------------------- journal
    def load_journal(self) -> dict[str, Any] | None:
        p = self.path / JOURNAL
        return json.loads(p.read_text()) if p.is_file() else None

    def save_journal(self, journal: dict[str, Any], *, last_resort: bool = False) -> None:
        """Write the journal atomically. ``last_resort`` (the failure record): on a full disk, release the
        reserve and try once more, so the session still ends ``failed`` with its reason on disk."""
        journal["updated"] = time.time()
        try:
            atomic_write_json(self.path / JOURNAL, journal)
        except OSError as exc:
            reserve = self.path / RESERVE
            if not (last_resort and exc.errno in _DISK_FULL and reserve.exists()):
                raise
            reserve.unlink()
            atomic_write_json(self.path / JOURNAL, journal)

    def write_session_info(self, config: dict[str, Any], views_done: int, turns_deg: list[float],
                           extra: dict[str, Any] | None = None) -> None:
        """session.json in the shared layout: the views captured so far with their commanded turns."""
        data = {"version": 1, "object": config.get("object"), "profile": config.get("profile"),
                "seed": config.get("seed"), "config": config,
                "views": [{"index": k, "commanded_turn_deg": float(turns_deg[k])} for k in range(views_done)]}
        turn_sigma = config.get("turn_accuracy_deg")
        if isinstance(turn_sigma, (int, float)) and turn_sigma > 0:  # the turn accuracy the cell stated
            data["turn_accuracy_deg"] = float(turn_sigma)
        data.update(extra or {})
        write_session(self.path, data)

    # ----------------------------------------------------------------------------------- scans
    def has_scan(self, view: int, scan: int) -> bool:
        return scan_complete(self.path, view, scan)

    def save_scan(self, view: int, scan: int, frame: RGBDFrame, extra: dict[str, Any] | None = None) -> None:
        write_scan(self.path, view, scan, frame, extra)

    def load_scan(self, view: int, scan: int) -> RGBDFrame:
        return read_scan(self.path, view, scan)

    # ----------------------------------------------------------------------------------- views
    def save_view(self, result: ViewResult) -> None:
        d = view_dir(self.path, result.view)
        write_ply(d / "object.ply", result.cloud)
        atomic_write_json(d / "view.json", {
            "view": result.view, "center": result.center, "height": result.height,
            "table": {"normal": result.table.normal, "offset": result.table.offset, "center": result.table.center},
            "scan_poses": result.scan_poses, "figures": result.figures})

    def has_view(self, view: int) -> bool:
        d = view_dir(self.path, view)
        return (d / "view.json").is_file() and (d / "object.ply").is_file()

    def load_view(self, view: int) -> ViewResult:
        d = view_dir(self.path, view)
        meta = json.loads((d / "view.json").read_text())
        cloud: PointCloud = read_ply(d / "object.ply")
        t = meta["table"]
        table = Plane(normal=np.asarray(t["normal"], float), offset=float(t["offset"]),
                      center=np.asarray(t["center"], float))
        poses = np.asarray(meta["scan_poses"], float).reshape(-1, 4, 4)  # none: (0, 4, 4), as the wire wants
        return ViewResult(view=int(meta["view"]), cloud=cloud, table=table, center=np.asarray(meta["center"], float),
                          height=float(meta["height"]), scan_poses=poses, figures=meta.get("figures", {}))

    def save_json(self, relative: str, data: Any) -> None:
        atomic_write_json(self.path / relative, data)

    def load_json(self, relative: str) -> Any:
        p = self.path / relative
        return json.loads(p.read_text()) if p.is_file() else None

    def save_model(self, cloud: PointCloud) -> Path:
        return write_ply(self.path / MODEL_FILE, cloud)
