"""``objscan scan``: one whole acquisition, with a live progress bar; starts the services it needs.

With no cell running it starts the embedded default (a router on loopback and every service as its own
process, sim backends) and stops what it started at the end. ``--resume SESSION_DIR`` continues a session
whose orchestrator was killed or stopped, re-using every frame already captured.
"""

from __future__ import annotations

import json
import queue
import signal
import socket
import sys
import time
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from common import keys
from common.client import live_services, request_sync
from common.codec import decode
from common.errors import ObjscanError
from common.launcher import ServiceGroup
from common.messages import Ok, Request
from common.zenoh_config import DEFAULT_ROUTER_PORT
from services.cli.cells import SERVICE_MODULES, cell_specs

console = Console()


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("scan", help="run a whole acquisition: views, grasps, turns, model",
                       description="Acquire a model of an object: 12 views 30 degrees apart by default. Starts "
                                   "the services (sim backends) when none are running.")
    p.add_argument("--object", default="milk", help="HOPE object name or mesh path (sim) (default: %(default)s)")
    p.add_argument("--views", type=int, default=12)
    p.add_argument("--profile", default="robot-turned", choices=["ideal", "hand-turned", "robot-turned"],
                   help="sim error profile (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--out", help="session folder (default: sessions/<object>-<time>)")
    p.add_argument("--resume", metavar="SESSION_DIR", help="continue an interrupted session")
    p.add_argument("--backend", choices=["sim", "real"], default="sim",
                   help="hardware backends when services must be started (default: %(default)s)")
    p.add_argument("--arm-backend", choices=["sim", "dynamixel"],
                   help="arm backend when the arm must be started (default: as --backend); dynamixel with "
                        "--emulate-bus runs the real DYNAMIXEL driver against an emulated bus driving the twin")
    p.add_argument("--emulate-bus", action="store_true",
                   help="dynamixel arm: emulate the configured servos (PAPRAS: DYNAMIXEL-P) on a pty, their "
                        "positions driving the twin (hardware in the loop, no hardware)")
    p.add_argument("--robot-config", help="dynamixel arm: robot configuration YAML (default: PAPRAS)")
    p.add_argument("--port", type=int, default=DEFAULT_ROUTER_PORT, help="router port of the cell")
    p.add_argument("--force-first-slip", action="store_true", help="sim: make the first grasp slip")
    p.add_argument("--no-incremental", action="store_true",
                   help="register every view pair at the end, not while the arm turns (the old, slower path)")
    p.add_argument("--no-record", action="store_true", help="do not record the session to session.mcap")
    p.add_argument("--library", help="model library folder the model is added to (default: the orchestrator's)")
    p.add_argument("--robot", default=keys.DEFAULT_ROBOT)
    p.set_defaults(func=run)


def _router_listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


def ensure_cell(port: int, backend: str, log_dir: Path, services: list[str] | None = None,
                extra_args: dict[str, list[str]] | None = None) -> ServiceGroup:
    """Join the cell on ``port``; start the router and whatever of ``services`` (default: all) is missing."""
    group = ServiceGroup(port, log_dir=log_dir, start_router=not _router_listening(port))
    if not _router_listening(port):
        try:
            group.start_router()
        except BaseException:
            group.stop_all()
            raise
    live = {s for s, _ in live_services(group.session, timeout=1.0)}
    wanted = services or list(SERVICE_MODULES)
    needed = [s for s in wanted if s not in live and not (s == "sim" and backend != "sim")]
    if needed:
        console.print(f"starting services: {', '.join(needed)} (logs in {log_dir})")
        try:
            group.launch(cell_specs(needed, backend=backend, extra_args=extra_args), timeout=180)
        except BaseException:
            group.stop_all()  # never leave half a cell behind
            raise
    return group


def arm_args(args) -> dict[str, list[str]]:  # noqa: ANN001
    """The arm service's own flags from ``--arm-backend``/``--emulate-bus``/``--robot-config``."""
    out: list[str] = []
    if args.emulate_bus and (args.arm_backend or "dynamixel") != "dynamixel":
        raise SystemExit("--emulate-bus needs --arm-backend dynamixel")
    if args.arm_backend or args.emulate_bus:
        out += ["--backend", args.arm_backend or "dynamixel"]
    if args.emulate_bus:
        out.append("--emulate-bus")
    if args.robot_config:
        out += ["--robot-config", str(Path(args.robot_config).resolve())]
    return {"arm": out} if out else {}


def run(args) -> int:  # noqa: ANN001
    t0 = time.time()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # unwind: the services this started are stopped
    session_dir = Path(args.resume or args.out or f"sessions/{Path(args.object).stem}-{time.strftime('%Y%m%d-%H%M%S')}")
    session_dir = session_dir.resolve()
    with ensure_cell(args.port, args.backend, session_dir / "logs", extra_args=arm_args(args)) as group:
        session = group.session
        updates: queue.Queue[dict[str, Any]] = queue.Queue()

        def on_status(sample) -> None:  # noqa: ANN001 - zenoh thread: decode and hand over
            try:
                msg = decode(sample.payload.to_bytes())
            except ObjscanError:
                return
            if isinstance(msg, Ok):
                updates.put(msg.info)

        sub = session.declare_subscriber(keys.orchestrator(args.robot, "status"), on_status)
        params: dict[str, Any]
        if args.resume:
            params = {"resume": str(session_dir)}
        else:
            params = {"out": str(session_dir), "config": {
                "object": args.object, "views": args.views, "profile": args.profile, "seed": args.seed,
                "width": args.width, "height": args.height, "force_first_slip": args.force_first_slip,
                                  "incremental": not args.no_incremental}}
            params["record"] = not args.no_record
            if args.library:
                params["library"] = str(Path(args.library).resolve())
        reply = request_sync(session, keys.orchestrator(args.robot, "run"), Request(params=params), timeout=30)
        console.print(f"session: {reply.info['session']}" + (" (resumed)" if reply.info.get("resumed") else ""))
        stop_sent = False

        def on_sigint(*_: object) -> None:
            nonlocal stop_sent
            if not stop_sent:
                stop_sent = True
                console.print("[yellow]stopping: e-stop sent to the arm[/yellow]")
                request_sync(session, keys.orchestrator(args.robot, "stop"), timeout=10)

        signal.signal(signal.SIGINT, on_sigint)
        final = _follow(updates, args.views if not args.resume else None)
        sub.undeclare()
    return _summary(final, session_dir, time.time() - t0)


def _follow(updates: queue.Queue[dict[str, Any]], views: int | None) -> dict[str, Any]:
    last: dict[str, Any] = {}
    columns = (TextColumn("[bold]{task.description}"), BarColumn(),
               TextColumn("{task.completed}/{task.total} views"), TimeElapsedColumn())
    with Progress(*columns, console=console) as progress:
        task = progress.add_task("starting", total=views or 12)
        while True:
            try:
                status = updates.get(timeout=1.0)
            except queue.Empty:
                continue
            last = status
            progress.update(task, total=status.get("views", views or 12), completed=status.get("views_done", 0),
                            description=f"view {status.get('view', 0)}: {status.get('state')}"
                                        + (f" (attempts {status['attempts']})" if status.get("attempts") else ""))
            if status.get("status") in ("done", "failed", "stopped"):
                return last


def _summary(final: dict[str, Any], session_dir: Path, seconds: float) -> int:
    status = final.get("status")
    if status == "done":
        console.print(f"[green]done[/green] in {seconds:.0f} s. model: {final.get('model')}")
        acc = final.get("accuracy")
        if acc:
            console.print("accuracy against ground truth: " + ", ".join(
                f"{k} {v:.3f}" for k, v in acc.items()))
        console.print(f"report: {session_dir / 'report.json'}")
        return 0
    err = final.get("last_error") or {}
    console.print(f"[red]{status}[/red] in state {final.get('state')}: {json.dumps(err)}")
    console.print(f"resume with: objscan scan --resume {session_dir}")
    return 1
