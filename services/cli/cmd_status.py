"""``objscan status``: the live services (liveliness) and what their health queries say."""

from __future__ import annotations

from rich.console import Console
from rich.table import Table

from common import keys
from common.client import live_services, request_sync
from common.errors import ObjscanError
from common.messages import Health
from common.zenoh_config import open_session
from services.cli.cells import add_network_args, network_settings


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("status", help="list live services and their health")
    add_network_args(p)
    p.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for answers")
    p.set_defaults(func=run)


def run(args) -> int:  # noqa: ANN001
    session = open_session(network_settings(args.connect))
    try:
        table = Table(title="objscan services")
        for col in ("service", "instance", "status", "busy", "uptime", "info"):
            table.add_column(col)
        live = live_services(session, timeout=args.timeout)
        for service, instance in live:
            try:
                h = request_sync(session, keys.health(service, instance), timeout=args.timeout)
                assert isinstance(h, Health)
                info = ", ".join(f"{k}={v}" for k, v in h.info.items() if not isinstance(v, dict))
                table.add_row(service, instance, h.status, str(h.busy), f"{h.uptime_s:.0f}s", info[:80])
            except ObjscanError as exc:
                table.add_row(service, instance, f"[red]{exc.code}[/red]", "-", "-", exc.message[:80])
        Console().print(table if live else "no live services found (is 'objscan up' running?)")
    finally:
        session.close()
    return 0
