"""``objscan down [--port P]``: stop a private cell (the router and services an ``objscan scan`` started for
itself, ``services/private_cell.py``), all of its processes, registration workers included.

The cell's keeper parks a running acquisition first (``stopped``, resumable with ``objscan scan --resume``),
then stops every service and the router; processes a keeper left behind (it was killed) are killed. Without
``--port``: the only private cell on this machine (several: name one; ``objscan status`` lists them).
Exit 0 when the cell is gone and its port free (or there was none to stop without ``--port``); 1 when
something still runs; 2 when the port names no private cell or several cells need a ``--port``.
"""

from __future__ import annotations

from common.errors import InvalidRequest, ObjscanError
from services.cli.outcome import FAILED, OK, print_json
from services.private_cell import private_cells, stop_cell


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("down", help="stop a private cell (its router and every service) that objscan scan started",
                       description="Stop a private cell: the router and services an 'objscan scan' started for "
                                   "itself. A running acquisition is parked as stopped (resumable) first.")
    p.add_argument("--port", type=int, help="router port of the private cell to stop (default: the only one; "
                                            "'objscan status' lists them)")
    p.add_argument("--timeout", type=float, default=60.0,
                   help="seconds the cell gets to stop cleanly before its processes are killed (default: %(default)s)")
    p.add_argument("--json", dest="json_output", action="store_true",
                   help="print one JSON object: port, session, stopped, left (pids still running), port_free")
    p.set_defaults(func=run)


def run(args) -> int:  # noqa: ANN001
    cells = private_cells()
    if args.port is not None:
        chosen = [c for c in cells if int(c["port"]) == args.port]
        if not chosen:
            raise InvalidRequest(f"no private cell on port {args.port}",
                                 detail={"ports": [c["port"] for c in cells]})
    elif len(cells) > 1:
        raise InvalidRequest("several private cells run: name one with --port "
                             f"({', '.join(str(c['port']) for c in cells)})",
                             detail={"ports": [c["port"] for c in cells]})
    else:
        chosen = cells
    if not chosen:
        if args.json_output:
            print_json({"port": None, "session": None, "stopped": False, "left": [], "port_free": True})
        else:
            print("no private cell runs on this machine")
        return OK
    cell = chosen[0]
    try:
        result = stop_cell(int(cell["port"]), timeout_s=args.timeout)
    except OSError as exc:
        raise ObjscanError(f"could not stop the cell on port {cell['port']}: {exc}", code="stop_failed") from None
    ok = not result["left"] and result["port_free"]
    if args.json_output:
        print_json({"port": cell["port"], "session": cell.get("session"), "stopped": ok,
                    "left": result["left"], "port_free": result["port_free"]})
    elif ok:
        print(f"stopped the private cell on port {cell['port']}"
              + (f" (session {cell['session']})" if cell.get("session") else ""))
    else:
        print(f"the private cell on port {cell['port']} is not fully stopped: still running {result['left']}, "
              f"port {'free' if result['port_free'] else 'still in use'}")
    return OK if ok else FAILED
