"""``objscan calibrate hand-eye``: find where the camera really sits on the hand, write the calibration file.

``--backend sim`` starts the twin, the arm and the camera (when not running), puts the ChArUco board on
the table and calibrates against the twin's seeded hand-eye error, reporting the error against its truth.
``--backend real`` (or ``--connect`` to a running cell) drives the real arm and D435 the same way; place the
printed board (``services/calibration/board.py``: 5 x 7 squares of 30 mm, DICT_4X4_50) flat at
``--board-xy``. The camera service loads the file at start (``--hand-eye FILE`` / ``$OBJSCAN_HAND_EYE``).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from common import keys
from common.api import MoveRequest
from common.client import request_sync
from common.errors import ObjscanError
from common.messages import Request
from common.session_folder import atomic_write_json
from common.zenoh_config import DEFAULT_ROUTER_PORT
from services.calibration.procedure import ProcedureConfig, run_procedure
from services.calibration.ros_files import write_ros_files
from services.cell import hardware_services
from services.cli.cells import add_network_args, remote_session
from services.cli.cmd_scan import console, ensure_cell
from services.cli.outcome import BadUsage


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("calibrate", help="calibrate the cell (hand-eye)",
                       description="Calibrate the cell. 'hand-eye': the camera's mount on the hand, from a ChArUco "
                                   "board seen from N arm poses.")
    kinds = p.add_subparsers(dest="kind", metavar="KIND", required=True)
    h = kinds.add_parser("hand-eye", help="solve AX=XB from N views of a ChArUco board; write the calibration file")
    h.add_argument("--backend", choices=["sim", "real"], default="sim",
                   help="start this cell when none runs (default: %(default)s); ignored with --connect")
    h.add_argument("--views", type=int, default=15, help="arm poses to try (default: %(default)s)")
    h.add_argument("--board-xy", type=float, nargs=2, default=(0.50, 0.0), metavar=("X", "Y"),
                   help="board centre on the table in base, metres (default: 0.50 0.0)")
    h.add_argument("--profile", default="hand-turned", help="sim: error profile (its hand-eye error is calibrated)")
    h.add_argument("--seed", type=int, default=0, help="sim: seed of the twin's hand-eye error; view plan seed")
    h.add_argument("--out", default="calibration/hand_eye.json", help="calibration file (default: %(default)s)")
    h.add_argument("--json", metavar="F", help="write the figures (errors against truth, residuals) to F")
    h.add_argument("--port", type=int, default=DEFAULT_ROUTER_PORT, help="router port of a local cell")
    h.add_argument("--robot", default=keys.DEFAULT_ROBOT,
                   help="robot cell id in the services' keys (default: %(default)s)")
    add_network_args(h)
    h.set_defaults(func=run)


def run(args) -> int:  # noqa: ANN001
    try:
        cfg = ProcedureConfig(views=args.views, board_xy=tuple(args.board_xy), seed=args.seed)
    except ValueError as exc:
        raise BadUsage(str(exc)) from None
    out = Path(args.out)
    t0 = time.time()
    if args.connect:
        session = remote_session(args.connect, hardware_services(args.backend))
        try:
            return _calibrate(session, args, cfg, out, t0)
        finally:
            session.close()
    with ensure_cell(args.port, args.backend, out.parent / "logs", services=hardware_services(args.backend)) as group:
        return _calibrate(group.session, args, cfg, out, t0)


def _calibrate(session, args, cfg: ProcedureConfig, out: Path, t0: float) -> int:  # noqa: ANN001
    if args.backend == "sim":  # with --connect too: the sim service must then be part of that cell
        x, y = cfg.board_xy
        request_sync(session, keys.sim(args.robot, "world"), Request(params={
            "op": "reset", "object": "charuco", "profile": args.profile, "seed": args.seed, "x": x, "y": y}),
            timeout=120)
    console.print(f"calibrating hand-eye over {cfg.views} views of the board at {cfg.board_xy}")
    try:
        res = run_procedure(session, args.robot, cfg)
    except ObjscanError as exc:  # the figures file says so too; the CLI's one line says why
        if args.json:
            atomic_write_json(Path(args.json), {"ok": False, "error": {"code": exc.code, "message": exc.message}})
        raise ObjscanError(f"calibration failed: {exc.message}", code=exc.code, detail=exc.detail) from exc
    finally:
        try:
            request_sync(session, keys.arm(args.robot, "move"), MoveRequest(kind="home", speed_scale=0.6), timeout=120)
        except ObjscanError as exc:  # parking is a courtesy: the calibration stands either way
            console.print(f"[yellow]could not move the arm home: {exc.code}[/yellow]")
    res.calibration.save(out)
    urdf, tf_static = write_ros_files(res.calibration.T_gripper_camera, out,
                                      note=f"{res.figures.get('seed_method', '')}, {time.strftime('%Y-%m-%d')}")
    f = {"ok": True, "file": str(out.resolve()), **res.figures, "seconds_total": round(time.time() - t0, 1),
         "urdf_joint": str(urdf.resolve()), "tf_static": str(tf_static.resolve())}
    f["T_gripper_camera"] = res.calibration.T_gripper_camera.tolist()
    f["correction"] = res.calibration.correction.tolist()
    if args.json:
        atomic_write_json(Path(args.json), f)
    console.print(f"views used {f['views_used']}/{cfg.views}; best closed form {f['seed_method']}; refined "
                  f"reprojection {f['reprojection_px']:.3f} px; correction {f['correction_mm']:.2f} mm / "
                  f"{f['correction_deg']:.3f} deg")
    if f["ground_truth"]:
        console.print(f"against the twin's truth: [bold]{f['translation_error_mm']:.3f} mm / "
                      f"{f['rotation_error_deg']:.4f} deg[/bold] (uncalibrated: {f['nominal_translation_error_mm']:.2f}"
                      f" mm / {f['nominal_rotation_error_deg']:.3f} deg)")
    console.print(f"wrote {out} (load it with: camera service --hand-eye {out}, or OBJSCAN_HAND_EYE={out})")
    console.print(f"for ROS 2: {urdf} (URDF joint gripper -> camera) and {tf_static} (static transform)")
    print(json.dumps({k: f[k] for k in ("translation_error_mm", "rotation_error_deg", "views_used", "file")}))
    return 0
