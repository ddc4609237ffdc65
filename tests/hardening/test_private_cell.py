"""A private cell belongs to its acquisition.

``objscan scan`` SIGKILLed mid-acquisition: the acquisition goes on headless (nothing lost), and once it has
ended with no client following it, every process of the cell (router, services, registration workers) is
gone and the port is free. While it runs, ``objscan scan --resume DIR`` attaches to it and Ctrl-C stops it;
``objscan status`` lists the cell (port, session, pid, state) and ``objscan down --port P`` stops it.
Before, the cell stayed up for good after the CLI died, and ``--resume`` answered ``session_locked``."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from common.zenoh_config import free_tcp_port
from services.private_cell import pid_alive, port_free, read_record, stop_cell
from tests.conftest import REPO, shared_data

FAST = ["--object", "milk", "--views", "3", "--profile", "ideal", "--physics", "geometric", "--width", "320",
        "--height", "240", "--no-record"]
"""The quickest whole acquisition the sim gives: 3 views, exact turns, the geometric grasp checker."""


def spawn(*args: str, out: Path) -> subprocess.Popen[bytes]:
    env = dict(os.environ, OMP_NUM_THREADS="1")
    with open(out, "wb") as fh:
        return subprocess.Popen([sys.executable, "-m", "services.cli.main", *args], cwd=REPO, env=env,
                                stdout=fh, stderr=subprocess.STDOUT, start_new_session=True)


def objscan(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, OMP_NUM_THREADS="1")
    return subprocess.run([sys.executable, "-m", "services.cli.main", *args], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=timeout)


def wait_for(predicate, timeout: float, what: str):  # noqa: ANN001, ANN201
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.5)
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")


def running_cell(port: int) -> dict | None:
    """The cell's record once its acquisition runs, else None."""
    rec = read_record(port)
    return rec if rec and rec.get("status") == "running" and rec.get("session") else None


def journal(session: Path) -> dict:
    try:
        return json.loads((session / "journal.json").read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return {}


def kill_cli_mid_scan(tmp_path: Path, grace: float) -> tuple[int, Path, dict]:
    """Start a scan in a private cell, SIGKILL the CLI once the acquisition runs; the cell's record."""
    shared_data("hope", "milk")
    port, session = free_tcp_port(), tmp_path / "session"
    cli = spawn("scan", *FAST, "--out", str(session), "--port", str(port), "--library", str(tmp_path / "models"),
                "--cell-grace", str(grace), "--json", out=tmp_path / "cli.out")
    try:
        rec = wait_for(lambda: running_cell(port), 300, "the acquisition to run")
    except BaseException:
        stop_cell(port)
        raise
    finally:
        os.killpg(cli.pid, signal.SIGKILL)  # no clean-up of any kind: the terminal is gone
        cli.wait(10)
    return port, session, rec


@pytest.fixture
def cleanup():
    """Ports whose private cell is stopped after the test, whatever happened in it."""
    ports: list[int] = []
    yield ports
    for port in ports:
        if read_record(port) is not None:
            stop_cell(port)


def group_members(pgids: set[int]) -> list[int]:
    """Running processes in any of these process groups (each service leads its own: its workers are in it)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if fields[0] != "Z" and int(fields[2]) in pgids:
            out.append(int(stat.parent.name))
    return out


def cell_gone(port: int, rec: dict) -> bool:
    return not pid_alive(rec["pid"]) and not group_members(set(rec["processes"].values())) \
        and port_free(port) and read_record(port) is None


@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_a_killed_cli_leaves_an_acquisition_that_finishes_then_its_cell_stops(tmp_path, cleanup):
    port, session, rec = kill_cli_mid_scan(tmp_path, grace=2.0)
    cleanup.append(port)
    assert {"router", "orchestrator", "registration"} <= set(rec["processes"])
    assert all(pid_alive(p) for p in rec["processes"].values())  # the acquisition goes on headless
    final = wait_for(lambda: journal(session).get("status") in ("done", "failed", "stopped")
                     and journal(session), 900, "the headless acquisition to end")
    assert final["status"] == "done", final.get("error")  # nothing lost: it finished without its CLI
    wait_for(lambda: cell_gone(port, rec), 60, "the private cell to stop itself")


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_resume_attaches_to_the_running_acquisition_status_lists_the_cell_and_down_stops_it(tmp_path, cleanup):
    port, session, rec = kill_cli_mid_scan(tmp_path, grace=600.0)
    cleanup.append(port)
    attached = spawn("scan", "--resume", str(session), "--port", str(port), out=tmp_path / "attach.out")
    try:
        wait_for(lambda: "attached" in (tmp_path / "attach.out").read_text(), 120, "the resume to attach")
        time.sleep(2.0)  # its Ctrl-C handler is set just after that line
        assert journal(session).get("status") == "running"  # attaching started nothing a second time
        os.kill(attached.pid, signal.SIGINT)  # Ctrl-C stops it, as in a normal scan
        assert attached.wait(60) == 1  # README: 1 = the job ran and did not succeed (stopped)
    finally:
        if attached.poll() is None:
            os.killpg(attached.pid, signal.SIGKILL)
    said = (tmp_path / "attach.out").read_text()
    assert "session_locked" not in said and "acquisition stopped; the arm confirmed its e-stop" in said, said
    assert journal(session)["status"] == "stopped"
    # the acquisition is over and nobody follows it, but the grace period keeps the cell: status lists it
    res = objscan("status", "--json", "--connect", f"tcp/127.0.0.1:{port}")
    assert res.returncode == 0, res.stderr
    cells = {c["port"]: c for c in json.loads(res.stdout)["cells"]}
    assert cells[port]["session"] == str(session) and cells[port]["pid"] == rec["pid"]
    assert cells[port]["state"] == "idle" and cells[port]["status"] == "stopped"
    res = objscan("down", "--port", str(port))
    assert res.returncode == 0 and f"stopped the private cell on port {port}" in res.stdout, res
    assert cell_gone(port, rec)  # every process (registration workers with their service) and the port
    assert objscan("down", "--port", str(port)).returncode == 2  # nothing there any more: said, not ignored
