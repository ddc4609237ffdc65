"""``objscan scan``: one whole acquisition, with a live progress bar; starts the services it needs.

With no cell running it starts the embedded default (a router on loopback and every service as its own
process, sim backends) and stops what it started at the end. A cell started by ``objscan scan`` belongs to
that run (a lock file per port, ``cell_lock_path``): a second ``objscan scan`` on the machine does not join
it (it would share its orchestrator and status key and be stopped when the first exits) but
starts a private cell on a free port, unless ``--port`` names the cell to join. ``--resume SESSION_DIR``
continues a session whose orchestrator was killed, stopped or failed, re-using every frame already captured;
on a session whose acquisition is still running (its CLI was killed, the private cell went on) it attaches:
it shows the progress, and Ctrl-C stops it as in a normal scan.

A cell this command starts from nothing is a private cell kept by its own process (``services/private_cell.py``):
the acquisition goes on if the CLI dies, and the cell stops itself ``--cell-grace`` seconds after the
acquisition ends with no client following it; ``objscan status`` lists private cells, ``objscan down`` stops one.
The orchestrator this command starts is confined to the session's parent folder and ``--library``.
"""

from __future__ import annotations

import fcntl
import os
import queue
import signal
import socket
import sys
import time
from collections.abc import Mapping
from pathlib import Path, PurePosixPath
from typing import Any

from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from common import keys
from common.client import live_services, request_sync
from common.codec import decode
from common.errors import ObjscanError
from common.launcher import ServiceGroup
from common.messages import Ok, Request
from common.session_folder import MODEL_FILE, REPORT_FILE
from common.zenoh_config import DEFAULT_ROUTER_PORT, free_tcp_port
from services.cell import SERVICE_MODULES, cell_specs, needs_twin
from services.cli.cells import add_network_args, remote_session, session_name
from services.cli.console import console
from services.cli.outcome import BadUsage, error_line, one_line, print_json, require_path, warn_unaccepted
from services.cli.scan_config import FLAG_KEYS, add_config_args, scan_config
from services.cli.stop import StopOnInterrupt
from services.live import add_live_args, live_requested, open_live_view
from services.orchestrator.config import AcquisitionConfig
from services.private_cell import DEFAULT_GRACE_S, PrivateCell, cell_lock_path, find_cell, start_cell


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("scan", help="run a whole acquisition: views, grasps, turns, model",
                       description="Acquire a model of an object: 12 views 30 degrees apart by default. Starts "
                                   "the services (sim backends) when none are running.")
    add_config_args(p)
    p.add_argument("--out", help="session folder (default: sessions/<object>-<time>)")
    p.add_argument("--resume", metavar="SESSION_DIR",
                   help="continue an interrupted session (its own config is kept; config flags are refused)")
    p.add_argument("--backend", choices=["sim", "real"], default="sim",
                   help="hardware backends when services must be started (default: %(default)s)")
    p.add_argument("--arm-backend", choices=["sim", "dynamixel"],
                   help="arm backend when the arm must be started (default: as --backend); dynamixel with "
                        "--emulate-bus runs the real DYNAMIXEL driver against an emulated bus driving the twin")
    p.add_argument("--emulate-bus", action="store_true",
                   help="dynamixel arm: emulate the configured servos (PAPRAS: DYNAMIXEL-P) on a pty, their "
                        "positions driving the twin (hardware in the loop, no hardware)")
    p.add_argument("--robot-config", help="dynamixel arm: robot configuration YAML (default: PAPRAS)")
    p.add_argument("--port", type=int, default=None,
                   help=f"router port of the cell to join or start (default: {DEFAULT_ROUTER_PORT}, or a private "
                        "free port when another objscan scan owns that cell)")
    p.add_argument("--cell-grace", type=float, default=DEFAULT_GRACE_S, metavar="SECONDS",
                   help="a private cell this scan starts stops itself this long after its acquisition ends "
                        "with no client following it, e.g. when this command was killed (default: %(default)s)")
    p.add_argument("--force-first-slip", action="store_true", help="sim: make the first grasp slip")
    p.add_argument("--no-incremental", action="store_true",
                   help="register every view pair at the end, not while the arm turns (the old, slower path)")
    p.add_argument("--no-record", action="store_true", help="do not record the session to session.mcap")
    p.add_argument("--library", help="model library folder the model is added to (default: the orchestrator's)")
    p.add_argument("--export", action="store_true",
                   help="after a finished scan, export the model as a watertight textured mesh and a simulation "
                        "asset (MJCF, URDF, GLB, OBJ, PLY, STL) into SESSION/export (docs/export.md)")
    p.add_argument("--robot", default=keys.DEFAULT_ROBOT,
                   help="robot cell id in the services' keys (default: %(default)s)")
    add_network_args(p)
    add_live_args(p)
    p.add_argument("--json", dest="json_output", action="store_true",
                   help="no progress bar; print one JSON object at the end (status, session, model, accuracy)")
    p.set_defaults(func=run)


def _router_listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


def _claim_cell(port: int) -> int | None:
    """Take the lock of the cell on ``port`` (a file descriptor), or None when another process holds it."""
    fd = os.open(cell_lock_path(port), os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return None
    return fd


def ensure_cell(port: int | None, backend: str | Mapping[str, str], log_dir: Path, services: list[str] | None = None,
                extra_args: dict[str, list[str]] | None = None, keeper_grace: float | None = None
                ) -> ServiceGroup | PrivateCell:
    """Join the cell on ``port``; start the router and whatever of ``services`` (default: all) is missing.

    ``port=None``: the default port, unless the cell there was started by another ``objscan scan`` (its lock
    is held): then a private cell on a free port. A cell this call starts is locked until the group stops.
    With ``keeper_grace`` (``objscan scan``), a cell this call starts from nothing is a private cell kept by a
    process of its own (``services/private_cell.py``): it outlives a killed CLI and stops itself once its
    acquisition has ended and no client follows it for ``keeper_grace`` seconds.
    """
    explicit = port is not None
    port = port if port is not None else DEFAULT_ROUTER_PORT
    lock = _claim_cell(port)
    if lock is None and not explicit and _router_listening(port):
        port = free_tcp_port()
        console.print(f"another objscan scan owns the cell on port {DEFAULT_ROUTER_PORT}: starting a private "
                      f"cell on port {port}")
        lock = _claim_cell(port)
    listening = _router_listening(port)
    if listening and lock is not None:  # someone else's cell (objscan up, compose): join it, do not own it
        os.close(lock)
        lock = None
    if not listening and lock is not None and keeper_grace is not None:
        wanted = [s for s in services or list(SERVICE_MODULES) if not (s == "sim" and not needs_twin(backend))]
        console.print(f"starting a private cell on port {port}: {', '.join(wanted)} (logs in {log_dir}); it "
                      f"stops {keeper_grace:g} s after its acquisition ends with no client following it")
        return start_cell(port, lock, cell_specs(wanted, backend=backend, extra_args=extra_args), log_dir,
                          grace_s=keeper_grace)
    group = ServiceGroup(port, log_dir=log_dir, start_router=not listening)
    if lock is not None:
        group.cleanups.append(lambda: os.close(lock))
    if not listening:
        try:
            group.start_router()
        except BaseException:
            group.stop_all()
            raise
    live = {s for s, _ in live_services(group.session, timeout=1.0)}
    wanted = services or list(SERVICE_MODULES)
    needed = [s for s in wanted if s not in live and not (s == "sim" and not needs_twin(backend))]
    if needed:
        console.print(f"starting services: {', '.join(needed)} (logs in {log_dir})")
        try:
            group.launch(cell_specs(needed, backend=backend, extra_args=extra_args), timeout=180)
        except BaseException:
            group.stop_all()  # never leave half a cell behind
            raise
    return group


def arm_args(args) -> dict[str, list[str]]:  # noqa: ANN001
    """The arm service's arguments from ``--arm-backend``/``--emulate-bus``/``--robot-config``: the backend and
    its options (``--option KEY=VALUE``)."""
    out: list[str] = []
    if args.emulate_bus and (args.arm_backend or "dynamixel") != "dynamixel":
        raise BadUsage("--emulate-bus needs --arm-backend dynamixel")
    if args.arm_backend or args.emulate_bus:
        out += ["--backend", args.arm_backend or "dynamixel"]
    if args.emulate_bus:
        out += ["--option", "emulate_bus=true"]
    if args.robot_config:
        out += ["--option", f"robot_config={Path(args.robot_config).resolve()}"]
    return {"arm": out} if out else {}


def _check_resume(args) -> None:  # noqa: ANN001
    """``--resume`` continues a session with the config it was started with: config flags are refused, and a
    local session folder must exist (nothing is started for one that does not)."""
    given = [f"--{k.replace('_', '-')}" for k in (*FLAG_KEYS, "config") if getattr(args, k, None) is not None]
    if given:
        raise BadUsage(f"--resume keeps the session's own config: drop {', '.join(given)}")
    if not args.connect:
        require_path(args.resume, "session folder")


def run(args) -> int:  # noqa: ANN001
    t0 = time.time()
    console.quiet = bool(args.json_output)  # stdout is the JSON document only
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # unwind: the services this started are stopped
    if args.resume:
        _check_resume(args)
        config = None
    else:  # checked here, before any service starts: a bad file or flag is said at once, naming the key
        config = scan_config(args)
        if not args.connect and _names_a_file(config.object):  # a remote cell's paths are its own
            require_path(config.object, "object mesh")
    name = args.resume or args.out or \
        f"sessions/{Path(config.object if config else 'session').stem}-{time.strftime('%Y%m%d-%H%M%S')}"
    if args.connect:  # a remote cell (compose, another machine): its orchestrator owns the sessions folder
        try:
            target = session_name(name)
        except ValueError as exc:  # a host path or '..': the cell's orchestrator owns the sessions folder
            raise BadUsage(str(exc)) from None
        session = remote_session(args.connect, ["orchestrator"])
        try:
            return _acquire(session, args, config, target, local=False, t0=t0)
        finally:
            session.close()
    session_dir = Path(name).resolve()
    if args.resume:  # its acquisition may still run in a private cell (a killed CLI's): follow it there
        kept = find_cell(session_dir)
        if kept is not None:
            console.print(f"the private cell on port {kept['port']} works on this session: attaching")
            with PrivateCell(int(kept["port"]), owner=False) as cell:
                return _acquire(cell.session, args, config, str(session_dir), local=True, t0=t0)
    # the orchestrator started here may write only the session's parent folder and the named library
    orchestrator_args = ["--sessions", str(session_dir.parent)]
    if args.library:
        orchestrator_args += ["--library", str(Path(args.library).resolve())]
    sim_args = twin_args(config) if config is not None else []
    with ensure_cell(args.port, args.backend, session_dir / "logs",
                     extra_args={"orchestrator": orchestrator_args, **arm_args(args),
                                 **({"sim": sim_args} if sim_args else {})},
                     keeper_grace=args.cell_grace) as group:
        # a joined cell's orchestrator (objscan up, compose) writes under its own --sessions root: without
        # --out, name the session and let it place it there (a local absolute path would be refused)
        joined = "orchestrator" not in group.procs
        target = session_dir.name if joined and not args.out and not args.resume else str(session_dir)
        code = _acquire(group.session, args, config, target, local=True, t0=t0)
    if code == 0 and getattr(args, "export", False):
        code = export_after_scan(session_dir, quiet=bool(args.json_output))
    return code


def export_after_scan(session_dir: Path, *, quiet: bool) -> int:
    """``--export``: the finished session exported into ``SESSION/export``; 1 with one line when it fails.

    The scan's own JSON document (``--json``) stays the only thing on stdout: the export's figures are in
    ``SESSION/export/export.json``.
    """
    from services.export import export_session

    if not (session_dir / MODEL_FILE).is_file():
        print(one_line(f"objscan scan: --export: {session_dir} holds no model.ply here (a remote or joined "
                       "cell's session): run objscan export on it where it is"), file=sys.stderr)
        return 1
    try:
        r = export_session(session_dir, session_dir / "export")
    except ObjscanError as exc:
        print(one_line(f"objscan scan: export failed: {exc.message} [{exc.code}]"), file=sys.stderr)
        return 1
    from services.cli.library_attach import store_with_library_entry

    store_with_library_entry(session_dir, "scan")  # the acquisition stored the model before this export
    if not quiet:
        console.print(f"exported to {session_dir / 'export'} in {r['seconds']:.1f} s: watertight "
                      f"{r['watertight']}, {r['parts']} convex part(s), files: "
                      + ", ".join(f for files in r["files"].values() for f in files[:1]))
    return 0


def _names_a_file(obj: str) -> bool:
    """Whether ``--object`` names a mesh file or folder (a path, or a mesh file name), not a catalogue name."""
    from services.sim.catalogue import MESH_SUFFIXES

    return os.sep in obj or Path(obj).suffix.lower() in MESH_SUFFIXES


def twin_args(config: AcquisitionConfig) -> list[str]:
    """The twin's start flags for a cell started for this scan: it starts with the scan's object in its units and
    upright axis, so an object it cannot load stops the start with the twin's own error (``object_not_found``
    and what it knows), and a mesh path is one it may load (its object roots are otherwise HOPE and folders)."""
    from services.sim.object_roots import start_args

    out = start_args(config.object) or ["--object", config.object]
    if config.object_scale is not None:
        out += ["--scale", repr(config.object_scale)]
    if config.object_up_axis is not None:
        out.append(f"--up-axis={config.object_up_axis}")
    return out


def config_params(config: AcquisitionConfig) -> dict[str, Any]:
    """The ``config`` map of the orchestrator's ``run`` request: the keys that differ from the defaults (the
    orchestrator fills in the same defaults, so it builds exactly ``config``)."""
    defaults = AcquisitionConfig().to_dict()
    return {k: v for k, v in config.to_dict().items() if v != defaults[k]}


def _acquire(session, args, config: AcquisitionConfig | None, target: str, *, local: bool,  # noqa: ANN001
             t0: float) -> int:
    """Start (or resume) the acquisition at ``target`` and follow it to the end."""
    updates: queue.Queue[dict[str, Any]] = queue.Queue()

    def on_status(sample) -> None:  # noqa: ANN001 - zenoh thread: decode and hand over
        try:
            msg = decode(sample.payload.to_bytes())
        except ObjscanError:
            return
        if isinstance(msg, Ok):
            updates.put(msg.info)

    sub = session.declare_subscriber(keys.orchestrator(args.robot, "status"), on_status)
    live = open_live_view(args) if live_requested(args) else None
    if live is not None:
        live.subscribe(session, args.robot)
        for sink in live.sinks:
            if hasattr(sink, "port"):
                console.print(f"Foxglove: connect to ws://127.0.0.1:{sink.port}")
    params: dict[str, Any]
    if args.resume:
        params = {"resume": target}
    else:
        assert config is not None  # a new scan always has one (run builds it)
        params = {"out": target, "config": config_params(config), "record": not args.no_record}
        if args.library:
            params["library"] = str(Path(args.library).resolve())
    if live is not None:
        params["live"] = True  # the orchestrator publishes each exchange on its tap (services/live/tap.py)
    running = _running_acquisition(session, args.robot, target) if args.resume else None
    if running is not None:  # attach: follow it (Ctrl-C stops it) instead of starting it a second time
        mine = str(running["session"])
        console.print(f"session: {mine} (attached to its running acquisition; Ctrl-C stops it)")
        updates.put(running)
    else:
        reply = request_sync(session, keys.orchestrator(args.robot, "run"), Request(params=params), timeout=30)
        mine = str(reply.info["session"])
        console.print(f"session: {mine}" + (" (resumed)" if reply.info.get("resumed") else ""))
    on_sigint = StopOnInterrupt(lambda key, timeout: request_sync(session, key, timeout=timeout), args.robot,
                                lambda line: console.print(f"[yellow]{line}[/yellow]"))
    signal.signal(signal.SIGINT, on_sigint)
    try:
        final = _follow(updates, config.views if config is not None else None, session=mine)
        on_sigint.wait()  # the stop's answer (the arm's) is printed before the summary
    finally:
        sub.undeclare()
        if live is not None:
            time.sleep(0.5)  # the last exchanges (the model) travel just before the final status
            live.close()
    if args.json_output:
        return _summary_json(final, Path(mine), time.time() - t0)
    return _summary(final, Path(mine), time.time() - t0, resume_arg=mine if local else target)


def _running_acquisition(session, robot: str, target: str) -> dict[str, Any] | None:  # noqa: ANN001
    """The orchestrator's status when the acquisition it runs is the one at ``target``, else None."""
    try:
        reply = request_sync(session, keys.orchestrator(robot, "status"), timeout=10)
    except ObjscanError:
        return None  # no orchestrator answers: the run request says why
    status = reply.info if isinstance(reply, Ok) and isinstance(reply.info, dict) else {}
    if status.get("status") != "running" or not status.get("session"):
        return None
    theirs, want = PurePosixPath(str(status["session"])), PurePosixPath(target)
    # a local target is the absolute folder; a remote one (--connect) is relative to the cell's sessions root
    same = Path(theirs).resolve() == Path(want).resolve() if want.is_absolute() \
        else theirs.parts[-len(want.parts):] == want.parts
    return status if same else None


def _follow(updates: queue.Queue[dict[str, Any]], views: int | None, session: str | None = None) -> dict[str, Any]:
    """Show the progress of ``session`` (statuses of any other session on the same key are ignored)."""
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
            if session is not None and status.get("session") not in (None, session):
                continue
            last = status
            progress.update(task, total=status.get("views", views or 12), completed=status.get("views_done", 0),
                            description=f"view {status.get('view', 0)}: {status.get('state')}"
                                        + (f" (attempts {status['attempts']})" if status.get("attempts") else ""))
            if status.get("status") in ("done", "failed", "stopped"):
                return last


def _summary_json(final: dict[str, Any], session_dir: Path, seconds: float) -> int:
    """The scan's outcome as one JSON object: 0 when done, 1 otherwise (``error`` then holds the last one)."""
    status = final.get("status")
    doc = {"status": status, "state": final.get("state"), "session": str(session_dir),
           "model": final.get("model"), "accuracy": final.get("accuracy"), "views": final.get("views"),
           "views_done": final.get("views_done"), "seconds": round(seconds, 1),
           "report": str(session_dir / REPORT_FILE)}
    if final.get("accepted") is not None:
        doc["accepted"], doc["why"] = bool(final["accepted"]), final.get("why") or ""
        warn_unaccepted("scan", final)
    if status != "done":
        doc["error"] = final.get("last_error") or {"code": status or "unknown", "message": "scan did not finish"}
        print(error_line("scan", f"{status} in state {doc['error'].get('state') or final.get('state')}: "
                                 f"{doc['error'].get('message')}", str(doc["error"].get("code") or status)),
              file=sys.stderr)
    print_json(doc)
    return 0 if status == "done" else 1


def _summary(final: dict[str, Any], session_dir: Path, seconds: float, resume_arg: str | None = None) -> int:
    status = final.get("status")
    if status == "done":
        console.print(f"[green]done[/green] in {seconds:.0f} s. model: {final.get('model')}")
        acc = final.get("accuracy")
        if acc:
            console.print("accuracy against ground truth: " + ", ".join(
                f"{k} {v:.3f}" for k, v in acc.items()))
        console.print(f"report: {session_dir / REPORT_FILE}")
        warn_unaccepted("scan", final)
        return 0
    err = final.get("last_error") or {}
    print(error_line("scan", f"{status} in state {err.get('state') or final.get('state')}: "
                             f"{err.get('message') or 'scan did not finish'}; resume with: objscan scan --resume "
                             f"{resume_arg or session_dir}", str(err.get("code") or status or "failed")),
          file=sys.stderr)
    return 1
