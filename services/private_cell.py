"""A private cell: the router and services ``objscan scan`` starts for itself, kept by a process of their own.

Why a keeper process: the services must outlive the CLI that started them (a closed terminal or a killed CLI
must not lose the acquisition: it goes on headless and finishes), yet must not outlive the acquisition (a
finished scan left ten processes and gigabytes of memory holding the port until killed by hand). So the CLI
does not start the services itself: it starts a keeper (``python -m services.private_cell``, in a session of
its own) that starts them, watches the acquisition through the orchestrator's status, and stops them all
(router last, registration workers with their service) once no acquisition runs and no client follows it for
``grace`` seconds. ``objscan down`` asks the keeper to stop at once.

What other commands see, without a Zenoh session (a private cell is on this machine by definition):

- ``CELLS_DIR/<port>.json``: the cell's record (``port``, keeper ``pid``, ``session``, ``state``, the
  acquisition's ``status`` and ``view``, ``processes`` {label: pid}, ``grace_s``, ``log_dir``), written by the
  keeper; ``private_cells()`` reads them (``objscan status``).
- ``CELLS_DIR/<port>.follow``: a client following the acquisition (``objscan scan``, or ``scan --resume`` that
  attached) holds a shared ``flock`` on it; the keeper tests it without blocking. A killed client's lock goes
  with it, so "no client follows" needs no heartbeat.
- ``cell_lock_path(port)``: the lock of the cell's owner (held by the keeper, handed over by the CLI), so a
  second ``objscan scan`` starts a cell of its own instead of joining this one.
"""

from __future__ import annotations

import argparse
import fcntl
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

from common import keys
from common.client import request_sync
from common.errors import ObjscanError, ServiceStartError
from common.fatal import fatal_payload
from common.launcher import ProcessSpec, ServiceGroup
from common.messages import Ok
from common.zenoh_config import ZenohSettings, open_session

CELLS_DIR = Path(tempfile.gettempdir()) / "objscan-cells"
DEFAULT_GRACE_S = 10.0
"""How long a private cell stays up once no acquisition runs and no client follows it."""
START_TIMEOUT_S = 240.0  # the services' start-up (open3d, MuJoCo) on a loaded machine
POLL_S = 0.5


def cell_lock_path(port: int) -> Path:
    """The lock held by the owner of the cell ``objscan scan`` started on ``port``."""
    return Path(tempfile.gettempdir()) / f"objscan-cell-{port}.lock"


def record_path(port: int) -> Path:
    return CELLS_DIR / f"{port}.json"


def follow_lock_path(port: int) -> Path:
    return CELLS_DIR / f"{port}.follow"


# ------------------------------------------------------------------------------------------ registry
def write_record(record: dict[str, Any]) -> None:
    """Replace the cell's record atomically (a reader never sees half a file)."""
    CELLS_DIR.mkdir(parents=True, exist_ok=True)
    path = record_path(int(record["port"]))
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    tmp.write_text(json.dumps(record))
    os.replace(tmp, path)


def read_record(port: int) -> dict[str, Any] | None:
    try:
        return json.loads(record_path(port).read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None


def pid_alive(pid: int | None) -> bool:
    """Whether ``pid`` runs (a zombie, exited but not yet reaped by its parent, does not)."""
    if not pid:
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        stat = Path(f"/proc/{int(pid)}/stat").read_text()
        return stat.rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def _objscan_process(pid: int) -> bool:
    """Whether ``pid`` is still one of ours (a Python objscan module), not a recycled pid."""
    try:
        cmd = Path(f"/proc/{int(pid)}/cmdline").read_bytes().split(b"\0")
    except OSError:
        return False
    return any(part.startswith((b"services.", b"common.router", b"tests.")) for part in cmd)


def private_cells() -> list[dict[str, Any]]:
    """The private cells on this machine, by port: those whose keeper runs, and those whose keeper is gone
    but some process still runs (state ``orphaned``: ``objscan down`` cleans them up). Records of cells with
    nothing left running are removed."""
    if not CELLS_DIR.is_dir():
        return []
    out = []
    for path in sorted(CELLS_DIR.glob("*.json")):
        try:
            rec = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            continue
        if not pid_alive(rec.get("pid")):
            alive = [p for p in (rec.get("processes") or {}).values() if pid_alive(p) and _objscan_process(p)]
            if not alive:
                path.unlink(missing_ok=True)
                continue
            rec["state"] = "orphaned"
        out.append(rec)
    return sorted(out, key=lambda r: int(r["port"]))


def find_cell(session: Path) -> dict[str, Any] | None:
    """The private cell whose acquisition works on ``session`` (its keeper running), if any."""
    want = str(Path(session).resolve())
    for rec in private_cells():
        if rec.get("state") != "orphaned" and rec.get("session") and str(Path(rec["session"]).resolve()) == want:
            return rec
    return None


# ------------------------------------------------------------------------------------------ followers
def follow(port: int) -> int:
    """Say "a client follows this cell's acquisition" until the returned descriptor is closed."""
    CELLS_DIR.mkdir(parents=True, exist_ok=True)
    fd = os.open(follow_lock_path(port), os.O_RDWR | os.O_CREAT, 0o666)
    fcntl.flock(fd, fcntl.LOCK_SH)
    return fd


def followed(port: int) -> bool:
    """Whether some client follows the cell's acquisition (holds the follow lock)."""
    try:
        fd = os.open(follow_lock_path(port), os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)  # closing drops the lock if it was taken
    return False


def port_free(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) != 0


# ------------------------------------------------------------------------------------------ the CLI's side
class PrivateCell:
    """A client's handle on a private cell: its session, and (for the owner) stopping it when done.

    Shaped like the ``ServiceGroup`` the CLI gets for a joined cell (``port``, ``session``, ``procs``,
    ``stop_all``, a context manager). The owner (the scan that started it) stops the cell when it exits
    normally, as before; a killed owner leaves it to the keeper. A client that attached only stops following.
    """

    def __init__(self, port: int, *, owner: bool, keeper: subprocess.Popen[bytes] | None = None):
        self.port = port
        self.owner = owner
        self.keeper = keeper
        self.endpoint = f"tcp/127.0.0.1:{port}"
        self._follow_fd: int | None = follow(port)
        self._session: Any = None

    @property
    def record(self) -> dict[str, Any]:
        return read_record(self.port) or {}

    @property
    def procs(self) -> dict[str, int]:
        return dict(self.record.get("processes") or {})

    @property
    def session(self) -> Any:
        if self._session is None:
            self._session = open_session(ZenohSettings(mode="client", connect=[self.endpoint]))
        return self._session

    def stop_all(self) -> None:
        if self._session is not None:
            self._session.close()
            self._session = None
        if self.owner:
            stop_cell(self.port, keeper=self.keeper)
        if self._follow_fd is not None:
            os.close(self._follow_fd)
            self._follow_fd = None
        if self.owner and read_record(self.port) is None and not followed(self.port):
            follow_lock_path(self.port).unlink(missing_ok=True)  # the cell is gone: leave nothing behind

    def __enter__(self) -> PrivateCell:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop_all()


def start_cell(port: int, lock_fd: int, specs: list[ProcessSpec], log_dir: Path, *, grace_s: float,
               robot: str = keys.DEFAULT_ROBOT) -> PrivateCell:
    """Start a keeper for a new cell on ``port`` (its owner lock ``lock_fd`` is handed over to it) and wait
    until every service is live. Raises ``ServiceStartError`` when the cell cannot start: the dying service's own
    typed error (``common/fatal.py``) when it said why, else one naming the keeper's log."""
    log_dir = Path(log_dir)
    log_dir.mkdir(parents=True, exist_ok=True)
    record_path(port).unlink(missing_ok=True)
    CELLS_DIR.mkdir(parents=True, exist_ok=True)
    follow_fd = follow(port)  # followed from before the keeper's first look
    log = open(log_dir / "keeper.log", "ab")  # noqa: SIM115 - the keeper's own copy stays open in it
    try:
        keeper = subprocess.Popen(
            [sys.executable, "-m", "services.private_cell", "--port", str(port), "--log-dir", str(log_dir),
             "--grace", str(grace_s), "--robot", robot, "--lock-fd", str(lock_fd),
             "--specs", json.dumps([asdict(s) for s in specs])],
            stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True,
            pass_fds=(lock_fd,))
    finally:
        log.close()
        os.close(lock_fd)  # the keeper holds the owner lock now
    cell = PrivateCell(port, owner=True, keeper=keeper)
    os.close(follow_fd)  # the handle follows from here
    deadline = time.monotonic() + START_TIMEOUT_S
    while True:
        rec = read_record(port) or {}
        if rec.get("state") not in (None, "starting") and rec.get("pid") == keeper.pid:
            break
        if keeper.poll() is not None or time.monotonic() > deadline:
            break
        time.sleep(0.1)
    if rec.get("state") in (None, "starting", "failed") or keeper.poll() is not None:
        cell.stop_all()
        raise cell_start_error(port, rec.get("error"), log_dir / "keeper.log")
    return cell


def error_record(exc: BaseException) -> dict[str, Any]:
    """How the keeper records why its cell did not start: the typed error (a service's own, when one died
    starting: ``object_not_found`` ...), so the CLI reports that code, not the keeper's exception type."""
    if isinstance(exc, ObjscanError):
        return {"code": exc.code, "message": exc.message, "detail": fatal_payload("keeper", exc)["detail"]}
    return {"code": "internal", "message": f"{type(exc).__name__}: {exc}", "detail": {}}


def cell_start_error(port: int, error: Any, keeper_log: Path) -> ServiceStartError:
    """The error ``start_cell`` raises: the one the keeper recorded (its code kept), else "did not start"."""
    if isinstance(error, dict) and isinstance(error.get("code"), str):
        return ServiceStartError(str(error.get("message") or "the cell did not start"), code=error["code"],
                                 detail={**(error.get("detail") or {}), "port": port, "keeper_log": str(keeper_log)})
    why = f": {error}" if error else ""
    return ServiceStartError(f"the cell on port {port} did not start{why}; see {keeper_log}",
                             code="cell_not_started", detail={"port": port, "keeper_log": str(keeper_log)})


def stop_cell(port: int, *, keeper: subprocess.Popen[bytes] | None = None, timeout_s: float = 60.0
              ) -> dict[str, Any]:
    """Stop the private cell on ``port``: its keeper parks the acquisition (``stopped``, resumable) and stops
    every process, router last. Processes left by a keeper that is gone (or does not end in ``timeout_s``)
    are killed. Returns the cell's last record with ``left``: pids still running after all (none expected)
    and ``port_free``."""
    rec = read_record(port) or {"port": port, "processes": {}}
    pid = keeper.pid if keeper is not None else rec.get("pid")
    if pid and pid_alive(pid):
        os.kill(int(pid), signal.SIGTERM)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if keeper is not None and keeper.poll() is not None:
                break
            if keeper is None and not pid_alive(pid):
                break
            time.sleep(0.1)
        else:
            os.kill(int(pid), signal.SIGKILL)
        if keeper is not None:
            keeper.wait(timeout=10)
    procs = (read_record(port) or rec).get("processes") or rec.get("processes") or {}
    for p in procs.values():  # left behind: a keeper killed outright, or one that did not finish
        if pid_alive(p) and _objscan_process(p):
            try:
                os.killpg(int(p), signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and any(pid_alive(p) for p in procs.values()):
        time.sleep(0.1)
    while time.monotonic() < deadline and not port_free(port):
        time.sleep(0.1)
    record_path(port).unlink(missing_ok=True)
    return {**rec, "left": [p for p in procs.values() if pid_alive(p)], "port_free": port_free(port)}


# ------------------------------------------------------------------------------------------ the keeper
class Keeper:
    """Starts the cell, keeps its record, and stops it when its acquisition no longer needs it."""

    def __init__(self, port: int, specs: list[ProcessSpec], log_dir: Path, grace_s: float, robot: str):
        self.group = ServiceGroup(port, log_dir=log_dir, robot=robot)
        self.specs = specs
        self.grace_s = grace_s
        self.robot = robot
        self.stop = threading.Event()
        self.record: dict[str, Any] = {
            "port": port, "pid": os.getpid(), "state": "starting", "session": None, "status": None,
            "view": None, "processes": {}, "grace_s": grace_s, "log_dir": str(log_dir), "started": time.time(),
            "followed": True}

    def _write(self, **changes: Any) -> None:
        self.record.update(changes)
        write_record(self.record)

    def _acquisition(self) -> dict[str, Any] | None:
        """The orchestrator's status, or None when it did not answer."""
        try:
            reply = request_sync(self.group.session, keys.orchestrator(self.robot, "status"), timeout=2.0)
        except ObjscanError:
            return None
        return reply.info if isinstance(reply, Ok) and isinstance(reply.info, dict) else None

    def run(self) -> int:
        self._write()
        try:
            self.group.launch(self.specs, timeout=START_TIMEOUT_S)
        except Exception as exc:  # noqa: BLE001 - said in the record, typed, for the CLI waiting on it
            self._write(state="failed", error=error_record(exc))
            self.group.stop_all()
            return 1
        self._write(state="idle", processes={label: p.pid for label, p in self.group.procs.items()})
        idle_since: float | None = None
        running = False
        while not self.stop.is_set():
            orchestrator = self.group.procs.get("orchestrator")
            status = self._acquisition() if orchestrator is None or orchestrator.poll() is None else {}
            if status is not None:  # no answer: keep what was known (a busy orchestrator is not an ended run)
                running = status.get("status") == "running"
                self.record.update(session=status.get("session") or self.record["session"],
                                   status=status.get("status"), view=status.get("view"))
            is_followed = followed(self.group.port)
            now = time.monotonic()
            idle_since = None if running or is_followed else (idle_since or now)
            left = None if idle_since is None else max(0.0, self.grace_s - (now - idle_since))
            self._write(state="running" if running else "idle", followed=is_followed,
                        shutdown_in_s=None if left is None else round(left, 1))
            if left == 0.0:
                break
            self.stop.wait(POLL_S)
        self._write(state="stopping")
        if running:  # objscan down mid-acquisition: park it (journal says stopped, resumable) before the kill
            try:
                request_sync(self.group.session, keys.orchestrator(self.robot, "stop"), timeout=5.0)
            except ObjscanError:
                pass
        self.group.stop_all()
        record_path(self.group.port).unlink(missing_ok=True)
        if not followed(self.group.port):
            follow_lock_path(self.group.port).unlink(missing_ok=True)
        return 0


def main() -> None:
    p = argparse.ArgumentParser(description="keeper of a private objscan cell (started by objscan scan)")
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--log-dir", required=True)
    p.add_argument("--grace", type=float, default=DEFAULT_GRACE_S)
    p.add_argument("--robot", default=keys.DEFAULT_ROBOT)
    p.add_argument("--lock-fd", type=int, help="the owner lock handed over by the CLI (kept open until exit)")
    p.add_argument("--specs", required=True, help="JSON list of the processes to start")
    args = p.parse_args()
    specs = [ProcessSpec(**s) for s in json.loads(args.specs)]
    keeper = Keeper(args.port, specs, Path(args.log_dir), args.grace, args.robot)
    for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
        signal.signal(sig, lambda *_: keeper.stop.set())
    sys.exit(keeper.run())


if __name__ == "__main__":
    main()
