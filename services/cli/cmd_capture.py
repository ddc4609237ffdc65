"""``objscan capture``: one RGB-D frame through the camera service, written as color.png, depth.png, meta.json.

With ``--backend sim`` it starts the twin, the arm and the camera (when not running), places ``--object`` on
the table, moves the camera to the locate pose and captures; any other camera backend of
``services/camera/registry.py`` (``realsense``, ``replay``, ``png_folder``, ...) needs only the camera
service, its own options given with ``--option KEY=VALUE``.
The files follow the session folder layout (docs/session-folder.md).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from PIL import Image

from common import keys
from common.api import CaptureRequest, MoveRequest
from common.backend_options import option_pair
from common.client import request_sync
from common.messages import Request
from common.session_folder import atomic_write_bytes, atomic_write_json
from common.zenoh_config import DEFAULT_ROUTER_PORT
from services.camera.registry import BACKENDS as CAMERA_BACKENDS
from services.cell import CELLS, hardware_services
from services.cli.cells import add_network_args, remote_session
from services.cli.cmd_scan import console, ensure_cell
from services.cli.outcome import require_path
from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.planning import look_pose
from services.sim.demo_objects import DEFAULT_OBJECT


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("capture", help="capture one RGB-D frame to a folder",
                       description="Capture one frame (color.png, 16-bit depth.png, meta.json with intrinsics, "
                                   "depth_scale and T_base_camera) through the camera service.")
    p.add_argument("--backend", choices=list(CAMERA_BACKENDS), default="sim",
                   help="camera backend (services/camera/registry.py); sim starts the twin and the arm too")
    p.add_argument("--object", default=DEFAULT_OBJECT,
                   help="sim: a demo object (carton, can, flat_box), a HOPE name, or a mesh file or folder")
    p.add_argument("--profile", default="ideal", help="sim: error profile")
    p.add_argument("--seed", type=int, default=0, help="sim: seed of the profile's drawn errors (default: %(default)s)")
    p.add_argument("--width", type=int, default=640, help="image width in pixels (default: %(default)s)")
    p.add_argument("--height", type=int, default=480, help="image height in pixels (default: %(default)s)")
    p.add_argument("--session", help="replay: session folder to read frames from")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE", type=option_pair,
                   help="a camera backend's own option, passed to the camera service (repeatable), e.g. "
                        "--backend png_folder --option folder=DIR --option intrinsics=fx,fy,cx,cy")
    p.add_argument("--out", required=True, help="folder to write color.png, depth.png, meta.json")
    p.add_argument("--port", type=int, default=DEFAULT_ROUTER_PORT,
                   help="router port of the local cell to join or start (default: %(default)s)")
    p.add_argument("--json", dest="json_output", action="store_true",
                   help="print only one JSON object (out, valid_depth, capture_ms; or the error), no progress")
    add_network_args(p)
    p.set_defaults(func=run)


def _capture(s, args, robot: str):  # noqa: ANN001, ANN202 - zenoh session, argparse namespace
    """(frame, capture ms): on the sim, the board/object is placed and the camera aimed at it first."""
    if args.backend == "sim":
        cfg = AcquisitionConfig()
        x, y = cfg.workspace_center
        request_sync(s, keys.sim(robot, "world"), Request(params={
            "op": "reset", "object": args.object, "profile": args.profile, "seed": args.seed, "x": x, "y": y}),
            timeout=120)
        request_sync(s, keys.arm(robot, "move"), MoveRequest(
            kind="pose", target=look_pose(np.array([x, y, 0.0]), cfg.scan), frame="camera", speed_scale=0.6),
            timeout=120)
    t0 = time.perf_counter()
    frame = request_sync(s, keys.camera_capture(robot), CaptureRequest(width=args.width, height=args.height),
                         timeout=60)
    return frame, (time.perf_counter() - t0) * 1e3


def run(args) -> int:  # noqa: ANN001
    console.quiet = bool(args.json_output)  # stdout is the JSON document only
    if args.session:  # a replay camera reads this folder: a missing one is bad input, said before anything starts
        require_path(args.session, "session folder")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    backends = CELLS["sim"] if args.backend == "sim" else {"camera": args.backend}
    services = hardware_services(backends)
    camera = ["--option", f"session={args.session}"] if args.session else []
    camera += [a for key, value in args.option for a in ("--option", f"{key}={value}")]
    extra: dict[str, list[str]] = {"camera": camera} if camera else {}
    if args.backend == "sim":  # a mesh path: the twin started here may load it (services/sim/object_roots.py)
        from services.sim.object_roots import start_args

        if start_args(args.object):
            extra["sim"] = start_args(args.object)
    robot = keys.DEFAULT_ROBOT
    if args.connect:  # a running cell elsewhere: use its services, start nothing
        session = remote_session(args.connect, services)
        try:
            frame, ms = _capture(session, args, robot)
        finally:
            session.close()
    else:
        with ensure_cell(args.port, backends, out / "logs", services=services, extra_args=extra or None) as group:
            frame, ms = _capture(group.session, args, robot)
    import io

    for name, img in (("color.png", Image.fromarray(np.ascontiguousarray(frame.color), "RGB")),
                      ("depth.png", Image.fromarray(np.ascontiguousarray(frame.depth.astype("<u2"))))):
        buf = io.BytesIO()
        img.save(buf, format="PNG")
        atomic_write_bytes(out / name, buf.getvalue())
    meta = {"intrinsics": frame.intrinsics.as_dict(), "depth_scale": frame.depth_scale,
            "T_base_camera": frame.T_base_camera, "stamp": frame.stamp, "seq": frame.seq,
            "backend": args.backend, **{k: v for k, v in frame.meta.items()}}
    if frame.T_base_camera_true is not None:
        meta["ground_truth"] = {"T_base_camera": frame.T_base_camera_true}
    atomic_write_json(out / "meta.json", meta)
    valid = float((frame.depth > 0).mean())
    console.print(f"wrote {out}/color.png, depth.png, meta.json ({frame.intrinsics.width}x{frame.intrinsics.height}, "
                  f"{valid:.0%} valid depth, capture {ms:.0f} ms)")
    print(json.dumps({"out": str(out), "valid_depth": valid, "capture_ms": ms}))
    return 0
