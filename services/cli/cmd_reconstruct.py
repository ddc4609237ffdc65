"""``objscan reconstruct SESSION_DIR --out DIR``: the registration pipeline offline, on a session folder.

Static registration of every view, then the dynamic stage: ``DIR/views/view_KK.ply``, ``DIR/model.ply`` (in
``base`` of view 0) and ``DIR/report.json``. With ``--gt MESH`` (a mesh file or a HOPE object name) the
model is evaluated against the ground truth (Chamfer, accuracy, completeness, F-score at 2 and 5 mm);
when the session was simulated its true object pose at view 0 places the mesh, otherwise the model is
aligned to it first, as the paper does.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from common.atomic import atomic_write_bytes
from common.session_folder import REPORT_FILE
from services.cli.console import console
from services.cli.outcome import FAILED, OK, error_line, print_json, require_path, warn_unaccepted


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("reconstruct", help="register a recorded session folder into a model, offline",
                       description=__doc__.split("\n\n")[1] if __doc__ else None)
    p.add_argument("session", help="session folder (view_KK/scan_J/{color.png, depth.png, meta.json})")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--profile", default="default", choices=["default", "paper"],
                   help="static registration profile (default: %(default)s; paper: the paper's parameters)")
    p.add_argument("--workers", type=int, default=None,
                   help="worker processes for views and pair jobs (default: one per core from 4 cores up, else 1)")
    p.add_argument("--threads", type=int, default=None,
                   help="threads sharing views and pair jobs when no worker processes run "
                        "(default: one per core; 1: serial)")
    p.add_argument("--gt", help="ground-truth mesh path or HOPE object name, for evaluation")
    p.add_argument("--json", dest="json_output", action="store_true",
                   help="print one JSON object (model, accepted, why, accuracy, report, or error) on stdout")
    p.set_defaults(func=run)


def ground_truth_points(gt: str, session: Path, n: int = 100_000) -> tuple[np.ndarray, bool]:
    """GT surface samples, posed in base of view 0 when the session recorded the true pose."""
    from services.sim.catalogue import load_object
    from services.sim.ground_truth import posed, recorded_pose

    pts = load_object(gt).gt_points(n)
    T = recorded_pose(session)
    return (pts, False) if T is None else (posed(pts, T), True)


def run(args) -> int:  # noqa: ANN001
    """Exit 0 when a model was built (accepted or not: an unaccepted one is flagged on stderr and in the
    JSON), 1 when no model was built (the dynamic stage's error is printed; no accuracy figures)."""
    session, out = require_path(args.session, "session folder"), Path(args.out)  # before the heavy imports
    from services.registration.api import StaticConfig, reconstruct

    if args.gt:  # an unknown ground truth is said now, not after minutes of registration
        from services.sim.catalogue import resolve_object

        resolve_object(args.gt)
    t0 = time.perf_counter()
    console.quiet = bool(args.json_output)  # stdout is the JSON document only

    def progress(info: dict[str, Any]) -> None:
        console.print(" ".join(f"{k}={v}" for k, v in info.items() if not isinstance(v, (dict, list))))

    report = reconstruct(session, out, StaticConfig.for_profile(args.profile), progress=progress,
                         workers=args.workers, threads=args.threads)
    figures = report.get("model") if isinstance(report.get("model"), dict) else None
    built = figures is not None and "error" not in figures and figures.get("ply") is not None
    model = out / str(figures["ply"]) if built else None  # this run's model, never a file left by an earlier one
    if args.gt and model is not None:
        import open3d as o3d

        from services.registration.api import evaluate_model

        xyz = np.asarray(o3d.io.read_point_cloud(str(model)).points)
        gt, posed = ground_truth_points(args.gt, session)
        metrics = evaluate_model(xyz, gt, align=True, init_T=np.eye(4)) if posed else evaluate_model(xyz, gt)
        report["accuracy"] = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in metrics.items()}
        report["accuracy"]["gt_posed_from_session"] = posed
    report["seconds_total"] = round(time.perf_counter() - t0, 3)
    atomic_write_bytes(out / REPORT_FILE, json.dumps(report, indent=2, default=float).encode())
    if model is None:
        err = (figures or {}).get("error") or {"code": "no_model", "message": "no model was built", "detail": {}}
        print(error_line("reconstruct", f"no model: {err['message']}", err["code"]), file=sys.stderr)
        if args.json_output:
            print_json({"error": err, "accepted": False, "why": report.get("why", ""),
                        "report": str(out / REPORT_FILE)})
        return FAILED
    acc = report.get("accuracy", {})
    console.print(f"model: {model}; {report['seconds_total']:.1f} s"
                  + (f"; chamfer {acc['chamfer_mm']:.3f} mm, F@2mm {acc.get('fscore_2mm', 0):.3f}" if acc else ""))
    fc = report.get("focal_calibration")
    if fc and fc.get("applied"):
        console.print(f"intrinsics: fx, fy self-calibrated at import (x {fc['scale']:.4f}, fx {fc['fx_after']}): "
                      f"{fc['reason']}")
    warn_unaccepted("reconstruct", report)
    if args.json_output:
        print_json({"model": str(model), "accepted": bool(report.get("accepted", True)), "why": report.get("why", ""),
                    "views_left_out": figures.get("views_left_out", []), "accuracy": acc or None,
                    "seconds": report["seconds_total"], "report": str(out / REPORT_FILE)})
    return OK
