"""Twin acquisitions that really grasp, turn and place, made once and reused by the benchmarks.

``bench dynamic``'s robot-turned rows must come from acquisitions in which the twin's arm
grasped the object, turned it and set it down under MuJoCo contact physics, not from turns a profile draws.
Such an acquisition takes minutes, so it is run once per (object, profile, seed) as the user would run it,
``objscan scan --object NAME --physics mujoco --profile robot-turned --views 12 --seed S --out DIR``, in a
subprocess on a private router port, and kept in a folder the user names (``$OBJSCAN_BENCH_SESSION_DIR``):
a second benchmark run finds the finished session there and does not acquire again.

A session counts as finished when its ``journal.json`` says ``done``, ``failed`` or ``stopped``; a folder
without a finished journal (an interrupted run) is acquired again from scratch. A failed acquisition (e.g.
an object the arm cannot turn to the end) is kept and reported as such: the benchmark scores only ``done``.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from common.errors import ObjscanError

SESSION_DIR_ENV = "OBJSCAN_BENCH_SESSION_DIR"
FINISHED = ("done", "failed", "stopped")


class AcquisitionBenchError(ObjscanError):
    """A benchmark acquisition could not be asked for (bad arguments); a failed scan is a result, not this."""

    code = "bad_acquisition_request"


@dataclass(frozen=True)
class Acquired:
    """One twin acquisition as the benchmark found or made it."""

    path: str
    command: str  # the objscan command that made it (or would have, when reused)
    status: str  # the journal's status: done / failed / stopped, or "missing" (no journal after the run)
    views: int  # views with every scan saved
    reused: bool  # found finished in the session folder: not acquired in this run
    seconds: float | None  # wall time of the acquisition in this run (None when reused)
    cpu_s: float | None  # CPU seconds of the scan and every service it started (None when reused)
    error: Any = None  # the journal's error when not done

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def session_folder(root: Path, obj: str, *, profile: str, physics: str, seed: int) -> Path:
    """Where the acquisition of ``obj`` (a HOPE name or a mesh path) is kept under ``root``."""
    return Path(root) / f"{Path(obj).stem}_{profile}_{physics}_seed{seed}"


def journal_status(folder: Path) -> tuple[str, Any]:
    """(status, error) of a session folder's journal; ("missing", None) when it has none."""
    path = Path(folder) / "journal.json"
    if not path.is_file():
        return "missing", None
    journal = json.loads(path.read_text())
    return str(journal.get("status")), journal.get("error")


def views_saved(folder: Path, scans_per_view: int = 3) -> int:
    """Consecutive views from view 0 with all their scans saved."""
    k = 0
    while all((Path(folder) / f"view_{k:02d}" / f"scan_{j}" / "meta.json").is_file() for j in range(scans_per_view)):
        k += 1
    return k


def scan_command(obj: str, out: Path, *, profile: str, physics: str, seed: int, views: int, port: int) -> list[str]:
    """The ``objscan scan`` command line of one benchmark acquisition (a private cell on ``port``)."""
    return [sys.executable, "-m", "services.cli", "scan", "--object", obj, "--physics", physics, "--profile", profile,
            "--views", str(views), "--seed", str(seed), "--port", str(port), "--out", str(out), "--no-record",
            "--json"]


def _run_scan(cmd: list[str], log: Path) -> None:
    with open(log, "w") as fh:
        subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, check=False)


def _children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def acquire(obj: str, root: Path, *, profile: str = "robot-turned", physics: str = "mujoco", seed: int = 0,
            views: int = 12, run_scan: Callable[[list[str], Path], None] = _run_scan) -> Acquired:
    """The finished acquisition of ``obj`` under ``root``: reused when there, else made now.

    ``run_scan(cmd, log_path)`` runs the command (tests pass their own to check the reuse rule without a
    ten-minute scan)."""
    if views < 2:
        raise AcquisitionBenchError("an acquisition for the dynamic benchmark needs at least 2 views",
                                    detail={"views": views})
    from common.zenoh_config import free_tcp_port

    folder = session_folder(root, obj, profile=profile, physics=physics, seed=seed)
    status, error = journal_status(folder)
    shown = " ".join(["objscan", *scan_command(obj, folder, profile=profile, physics=physics, seed=seed,
                                               views=views, port=0)[3:]]).replace(" --port 0", "")
    if status in FINISHED:
        return Acquired(str(folder), shown, status, views_saved(folder), True, None, None, error)
    if folder.exists():  # an interrupted acquisition: start again rather than score half a session
        shutil.rmtree(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    cmd = scan_command(obj, folder, profile=profile, physics=physics, seed=seed, views=views, port=free_tcp_port())
    t0, c0 = time.perf_counter(), _children_cpu()
    run_scan(cmd, folder.parent / f"{folder.name}.log")
    seconds, cpu = time.perf_counter() - t0, _children_cpu() - c0
    status, error = journal_status(folder)
    return Acquired(str(folder), shown, status, views_saved(folder), False, round(seconds, 1), round(cpu, 1), error)


def session_root(default: Path) -> Path:
    """``$OBJSCAN_BENCH_SESSION_DIR`` when set (sessions kept and reused), else ``default``."""
    named = os.environ.get(SESSION_DIR_ENV, "").strip()
    return Path(named) if named else Path(default)
