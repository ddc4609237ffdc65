"""Two ``objscan scan`` runs on one machine do not share a cell.

Why: the second run found the first's cell on the default port and used it (same router, orchestrator and
status key); when the first exited it stopped that cell and the second acquisition ended ``stopped``
mid-view. Now a cell started by ``objscan scan`` is locked by it and a second run starts a private one."""

from __future__ import annotations

from common import keys
from common.client import request_sync
from common.messages import Ok
from common.zenoh_config import free_tcp_port
from services.cli import cmd_scan


def test_a_second_scan_starts_its_own_cell_and_outlives_the_first(tmp_path, monkeypatch):
    default = free_tcp_port()
    monkeypatch.setattr(cmd_scan, "DEFAULT_ROUTER_PORT", default)  # never the machine's real 7447
    first = cmd_scan.ensure_cell(None, "sim", tmp_path / "logs1", services=["orchestrator"])
    try:
        assert first.port == default and cmd_scan.cell_lock_path(default).exists()
        second = cmd_scan.ensure_cell(None, "sim", tmp_path / "logs2", services=["orchestrator"])
        try:
            assert second.port != first.port
            assert "orchestrator" in second.procs and "router" in second.procs  # its own, not the first's
            first.stop_all()  # the first run ends and stops its cell
            status = request_sync(second.session, keys.orchestrator(keys.DEFAULT_ROBOT, "status"), timeout=20)
            assert isinstance(status, Ok) and second.procs["orchestrator"].poll() is None
        finally:
            second.stop_all()
    finally:
        first.stop_all()


def test_an_explicit_port_joins_the_cell_there(tmp_path, monkeypatch):
    default = free_tcp_port()
    monkeypatch.setattr(cmd_scan, "DEFAULT_ROUTER_PORT", default)
    with cmd_scan.ensure_cell(None, "sim", tmp_path / "logs1", services=["orchestrator"]) as first, \
            cmd_scan.ensure_cell(first.port, "sim", tmp_path / "logs2", services=["orchestrator"]) as joined:
        assert joined.port == first.port and joined.procs == {}  # nothing started: the cell was complete
