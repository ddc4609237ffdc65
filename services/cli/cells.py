"""How the CLI joins an existing network (``--connect``, TLS variables) or names a session on a remote cell.

Which processes make up a cell is ``services/cell.py``. Commands that need services (scan, replay, capture)
reuse running ones when ``objscan status`` would find them, and start that set otherwise.
"""

from __future__ import annotations

import os

from common.zenoh_config import ZenohSettings


def network_settings(connect: str | None) -> ZenohSettings:
    """Settings for the CLI's own session: ``--connect`` wins, then the environment, then loopback."""
    s = ZenohSettings.from_env()
    if connect:
        s = s.with_overrides(connect=[e for e in connect.split(",") if e])
    return s


def add_network_args(p) -> None:  # noqa: ANN001 - argparse parser
    p.add_argument("--connect", default=os.environ.get("OBJSCAN_ZENOH_CONNECT"),
                   help="zenoh endpoint(s) of the cell (default: env OBJSCAN_ZENOH_CONNECT or tcp/127.0.0.1:7447)")


def remote_session(connect: str, needed: list[str], robot_services_timeout: float = 3.0):  # noqa: ANN201
    """A session on the cell at ``connect`` (with the TLS variables of the environment), once the services
    ``needed`` are live there; a clear error names the missing ones (nothing is started on a remote cell)."""
    from common.client import live_services
    from common.errors import ServiceUnavailable
    from common.zenoh_config import open_session

    try:
        session = open_session(network_settings(connect))
    except (FileNotFoundError, ValueError) as exc:  # a TLS file or setting named in the environment is wrong
        raise ServiceUnavailable(f"cannot join {connect}: {exc}", code="bad_network_config",
                                 detail={"connect": connect}) from None
    live = {s for s, _ in live_services(session, timeout=robot_services_timeout)}
    missing = [s for s in needed if s not in live]
    if missing:
        session.close()
        raise ServiceUnavailable(f"no {', '.join(missing)} service on {connect}: start the cell there first "
                                 "('docker compose up' or 'objscan up')", detail={"connect": connect,
                                                                                 "missing": missing})
    return session


def session_name(path: str) -> str:
    """What the CLI sends a remote orchestrator for ``--out``/``--resume``: a path relative to its sessions
    root (a leading ``sessions/`` is dropped), so the session lands inside the sessions volume whatever
    the client's own folders are. Absolute paths and ``..`` are refused: they name client folders."""
    from pathlib import PurePosixPath

    p = PurePosixPath(path)
    if p.is_absolute() or ".." in p.parts or not p.parts:
        raise ValueError(f"{path!r}: with --connect, give a session name relative to the cell's sessions root "
                         "(e.g. milk-001), not a path on this machine")
    if p.parts[0] == "sessions" and len(p.parts) > 1:
        p = PurePosixPath(*p.parts[1:])
    return str(p)
