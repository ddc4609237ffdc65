"""``objscan up``: start the router and every service as its own process; Ctrl-C stops them all.

With ``--connect`` (or ``OBJSCAN_ZENOH_CONNECT``) no router is started: the services join that network
(TLS variables included), e.g. to add registration workers on a second machine.
"""

from __future__ import annotations

import signal
import threading
import time
from pathlib import Path

from common.errors import ObjscanError
from common.launcher import ProcessSpec, ServiceGroup
from common.zenoh_config import DEFAULT_ROUTER_PORT
from services.cell import CELLS, SERVICE_MODULES, cell_specs
from services.cli.cells import add_network_args, network_settings
from services.cli.outcome import BadUsage, require_path


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("up", help="start every service (sim backends by default) and keep them running",
                       description="Start a Zenoh router on loopback and every objscan service as its own "
                                   "process. Ctrl-C (or SIGTERM) stops them all cleanly.")
    p.add_argument("--backend", choices=list(CELLS), default="sim",
                   help="the cell's hardware backends for camera and arm (services/cell.py CELLS; "
                        "default: %(default)s)")
    p.add_argument("--robot-config", help="robot configuration YAML for the dynamixel arm (default: PAPRAS, "
                                          "services/arm/robot/papras_dynamixel.yaml); see docs/arm.md")
    p.add_argument("--emulate-bus", action="store_true",
                   help="sim cell with the real DYNAMIXEL driver on an emulated bus driving the twin")
    p.add_argument("--port", type=int, default=DEFAULT_ROUTER_PORT, help="router port (default: %(default)s)")
    p.add_argument("--only", help=f"start only these services, comma-separated: {', '.join(SERVICE_MODULES)} "
                                  "(default: all)")
    p.add_argument("--log-dir", default="logs", help="one log file per process (default: %(default)s)")
    p.add_argument("--ros2", action="store_true",
                   help="also start the ROS 2 face: the cell as ROS 2 topics and scan services on rmw_zenoh keys "
                        "of the same router (docs/ros2.md); the orchestrator then publishes its exchanges")
    p.add_argument("--ros2-arg", action="append", default=[], metavar="ARG",
                   help="an argument for the ROS 2 face, repeatable, e.g. --ros2-arg=--domain-id=3 or "
                        "--ros2-arg=--hand-eye=calibration/hand_eye.json")
    add_network_args(p)
    p.set_defaults(func=run)


def arm_args(args) -> dict[str, list[str]]:  # noqa: ANN001
    """The arm's flags: the robot configuration (validated here first: a bad file fails before anything
    starts), and the emulated bus."""
    out: list[str] = []
    if args.robot_config:
        from services.arm.drivers.dynamixel.robot_config import load_robot_config

        require_path(args.robot_config, "robot configuration")

        load_robot_config(args.robot_config)
        out += ["--option", f"robot_config={Path(args.robot_config).resolve()}"]
    if args.emulate_bus:
        if args.backend != "sim":
            raise BadUsage("--emulate-bus runs with the sim cell (--backend sim)")
        out += ["--backend", "dynamixel", "--option", "emulate_bus=true"]
    return {"arm": out} if out else {}


def ros2_spec(extra: list[str]) -> ProcessSpec:
    """The ROS 2 face's process (``services/ros2``), with its own arguments."""
    return ProcessSpec("services.ros2", list(extra), service="ros2")


def run(args) -> int:  # noqa: ANN001
    names = [n for n in args.only.split(",") if n] if args.only else None
    unknown = set(names or []) - set(SERVICE_MODULES)
    if unknown:
        raise BadUsage(f"unknown services: {', '.join(sorted(unknown))} (known: {', '.join(SERVICE_MODULES)})")
    extra = arm_args(args)  # a bad robot configuration says which key (bad input, exit 2), and nothing starts
    stop = threading.Event()
    failure: ObjscanError | None = None
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    with ServiceGroup(args.port, log_dir=Path(args.log_dir), start_router=not args.connect) as group:
        if args.connect:  # join a running router (TLS variables honoured) instead of starting one
            group.settings = network_settings(args.connect)
            group.endpoint = args.connect
        if args.ros2:  # the face republishes frames, clouds and the model from the orchestrator's tap
            extra["orchestrator"] = [*extra.get("orchestrator", []), "--tap"]
        specs = cell_specs(names, backend=args.backend, extra_args=extra)
        if args.ros2:
            specs.append(ros2_spec(args.ros2_arg))
        what = f"joining {group.endpoint} with" if args.connect else f"starting router on {group.endpoint} and"
        print(f"{what} {len(specs)} services (logs in {args.log_dir}/)")
        group.launch(specs)
        print("all services live; Ctrl-C to stop. 'objscan status' lists them.")
        while not stop.is_set():
            for label, proc in group.procs.items():
                if proc.poll() is not None and failure is None:  # said once, as the command's failure, after the stop
                    failure = group.start_error(label, starting=False)
                    stop.set()
            time.sleep(0.5)
        print("stopping...")
    print("stopped.")
    if failure is not None:
        raise ObjscanError(f"the cell stopped: {failure.message}", code=failure.code, detail=failure.detail)
    return 0
