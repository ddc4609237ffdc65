"""``objscan status``: the live services (liveliness) and what their health queries say.

``--json`` prints one object, ``{"services": [{service, instance, status, busy, uptime_s, info}, ...],
"cells": [{port, session, pid, state, status, view, ...}, ...]}``: ``cells`` are the private cells on this
machine (those ``objscan scan`` started for itself, ``services/private_cell.py``), whatever network the
services come from; ``objscan down --port P`` stops one.
No router: exit 3 with one line (``no_router``); a router but no live service: exit 4 (``no_services``); the
private cells are listed before that line (under ``--json``, in the error's ``detail.cells``).
"""

from __future__ import annotations

import os
from dataclasses import replace
from typing import Any

from rich.console import Console
from rich.table import Table

from common import keys
from common.client import live_services, request_sync
from common.errors import ObjscanError, ServiceUnavailable
from common.messages import Health
from common.zenoh_config import open_session
from services.cli.cells import add_network_args, network_settings
from services.cli.outcome import print_json
from services.private_cell import private_cells


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("status", help="list live services and their health",
                       description="The live services of the network (liveliness) with what their health queries "
                                   "say, and the private cells on this machine. Exit 3: no router answers; exit 4: "
                                   "a router but no live service.")
    add_network_args(p)
    p.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for answers")
    p.add_argument("--json", dest="json_output", action="store_true", help="print one JSON object, no table")
    p.set_defaults(func=run)


def collect(session: Any, timeout: float) -> list[dict[str, Any]]:
    """One row per live service instance: its health, or the error its health query gave."""
    rows = []
    for service, instance in live_services(session, timeout=timeout):
        row: dict[str, Any] = {"service": service, "instance": instance}
        try:
            h = request_sync(session, keys.health(service, instance), timeout=timeout)
            if not isinstance(h, Health):
                raise ObjscanError(f"health answered with {type(h).__name__}", code="bad_message")
            row.update(status=h.status, busy=h.busy, uptime_s=round(float(h.uptime_s), 1), info=h.info)
        except ObjscanError as exc:
            row.update(status=exc.code, busy=None, uptime_s=None, info={"error": exc.message})
        rows.append(row)
    return rows


STATUS_CONNECT_TIMEOUT_MS = 4000  # a router on the LAN answers in milliseconds; say "no router" within ~15 s


def run(args) -> int:  # noqa: ANN001
    settings = network_settings(args.connect)
    if "OBJSCAN_ZENOH_CONNECT_TIMEOUT_MS" not in os.environ:
        settings = replace(settings, connect_timeout_ms=STATUS_CONNECT_TIMEOUT_MS)
    cells = [cell_row(c) for c in private_cells()]
    try:
        session = open_session(settings)
        try:
            rows = collect(session, args.timeout)
        finally:
            session.close()
        if not rows:
            raise ServiceUnavailable("no live services found (is 'objscan up' running?)", code="no_services")
    except ObjscanError as exc:
        if cells:  # say what runs on this machine before saying the network is not there
            exc.detail = {**(exc.detail or {}), "cells": cells}
            if not args.json_output:
                print_cells(cells)
        raise
    if args.json_output:
        print_json({"services": rows, "cells": cells})
        return 0
    table = Table(title="objscan services")
    for col in ("service", "instance", "status", "busy", "uptime", "info"):
        table.add_column(col)
    for r in rows:
        ok = r["uptime_s"] is not None
        info = ", ".join(f"{k}={v}" for k, v in r["info"].items() if not isinstance(v, dict))
        table.add_row(r["service"], r["instance"], r["status"] if ok else f"[red]{r['status']}[/red]",
                      str(r["busy"]) if ok else "-", f"{r['uptime_s']:.0f}s" if ok else "-", info[:80])
    Console().print(table)
    if cells:
        print_cells(cells)
    return 0


def cell_row(rec: dict[str, Any]) -> dict[str, Any]:
    """What ``status`` shows of a private cell's record."""
    return {"port": rec.get("port"), "session": rec.get("session"), "pid": rec.get("pid"),
            "state": rec.get("state"), "status": rec.get("status"), "view": rec.get("view"),
            "followed": rec.get("followed"), "shutdown_in_s": rec.get("shutdown_in_s"),
            "processes": rec.get("processes") or {}, "log_dir": rec.get("log_dir")}


def print_cells(cells: list[dict[str, Any]]) -> None:
    table = Table(title="private cells (objscan down --port P stops one)")
    for col in ("port", "session", "pid", "state", "acquisition", "processes"):
        table.add_column(col)
    for c in cells:
        state = str(c["state"]) + (f" (stops in {c['shutdown_in_s']:.0f}s)" if c.get("shutdown_in_s") is not None
                                   else "")
        acq = f"{c['status'] or '-'}" + (f", view {c['view']}" if c.get("view") is not None else "")
        table.add_row(str(c["port"]), str(c["session"] or "-"), str(c["pid"]), state, acq,
                      str(len(c["processes"])))
    Console().print(table)
