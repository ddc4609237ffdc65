"""``objscan reconstruct``: the offline pipeline over a session folder.

Reads the session (``common.session_folder``), registers each view's scans and isolates the object
(``services.registration.static``), writes ``OUT/views/view_KK.ply`` (object cloud in ``base``: xyz, rgb,
normals) and ``OUT/report.json`` (per-view figures, timings, ground-truth errors where the session has
truth). A view that fails (no table, no object, empty depth, ...) is reported with its error code and the
others go on. The dynamic stage (the 12 views into one model) plugs in at ``run_dynamic_stage``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from common.errors import ObjscanError
from common.session_folder import atomic_write_json, read_scan, read_session
from services.registration.cloud import write_ply
from services.registration.static import StaticConfig, ViewResult, register_view
from services.registration.static.evaluate import prior_pose_errors, relative_pose_errors

Progress = Callable[[dict[str, Any]], None]


def reconstruct(
    session_dir: str | Path, out_dir: str | Path, config: StaticConfig | None = None, progress: Progress | None = None
) -> dict[str, Any]:
    """Run static registration on every view of ``session_dir``; write PLYs and ``report.json`` to ``out_dir``.

    ``progress`` (optional) is called with a small dict after each view (``stage``, ``view``, ``of``,
    ``status``, ``seconds``) so a CLI can show progress. Returns the report (also written as JSON).
    Raises ``SessionFolderError`` only when the session itself is unreadable; per-view failures are in
    the report.
    """
    cfg = config or StaticConfig()
    session = read_session(Path(session_dir))
    out = Path(out_dir)
    (out / "views").mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    views_report: list[dict[str, Any]] = []
    results: dict[int, ViewResult] = {}
    n = len(session.views)
    for k, entry in enumerate(session.views):
        index = int(entry["index"])
        t0 = time.perf_counter()
        item: dict[str, Any] = {"index": index, "commanded_turn_deg": float(entry.get("commanded_turn_deg", 0.0))}
        try:
            scans = session.scans(index)
            if not scans:
                raise ObjscanError(f"view {index} has no complete scan", code="no_scans")
            frames = [read_scan(session.path, index, j) for j in scans]
            result = register_view(frames, cfg)
            ply = write_ply(out / "views" / f"view_{index:02d}.ply", result.object_cloud)
            item.update(result.to_json())
            item["ply"] = str(ply.relative_to(out))
            item["scan_indices"] = scans
            gt = _ground_truth(result, frames)
            if gt:
                item["ground_truth"] = gt
            results[index] = result
            status = "ok"
        except ObjscanError as exc:
            item["error"] = {"code": exc.code, "message": exc.message, "detail": exc.detail}
            status = "failed"
        item["seconds"] = round(time.perf_counter() - t0, 4)
        views_report.append(item)
        if progress is not None:
            progress(
                {"stage": "static", "view": index, "of": n, "done": k + 1, "status": status, "seconds": item["seconds"]}
            )

    report: dict[str, Any] = {
        "session": str(session.path),
        "object": session.data.get("object"),
        "profile": cfg.profile,
        "config": cfg.as_dict(),
        "views": views_report,
        "summary": _summary(views_report, time.perf_counter() - t_start),
    }
    report["model"] = run_dynamic_stage(results, session, out, report, progress)
    atomic_write_json(out / "report.json", report)
    return report


# ==================================================================================================
# DYNAMIC STAGE -- the hook for dynamic registration (issue: dynamic scan registration, paper II-C).
# The dynamic-registration engineer replaces the body below with the call into
# ``services.registration.dynamic`` (not imported here yet): it receives every successful view's
# ``ViewResult`` (object cloud, table plane, object centre; keyed by view index), the session (for the
# commanded turns: ``session.commanded_turn_deg(k)``) and ``out_dir``; it writes the model (e.g.
# ``out_dir/model.ply``) and returns the JSON-able figures that go into ``report["model"]``.
# ==================================================================================================
def run_dynamic_stage(
    results: dict[int, ViewResult],
    session: Any,
    out_dir: Path,
    report: dict[str, Any],
    progress: Progress | None = None,
) -> dict[str, Any] | None:
    """Dynamic registration of the views into one model: writes ``out_dir/model.ply``, returns its figures.

    Views are taken in index order with their commanded cumulative turns; fewer than 3 usable views
    (or a dynamic-stage error) is reported in the returned figures, not raised, like a failed view.
    """
    from services.registration.dynamic.model import DynamicConfig, build_model
    from services.registration.dynamic.views import view_from_static

    t0 = time.perf_counter()
    order = sorted(results)
    views = [view_from_static(results[k], session.commanded_turn_deg(k), index=k) for k in order]
    say = (lambda stage, info: progress({"stage": f"dynamic:{stage}", **info})) if progress else None
    try:
        model = build_model(views, DynamicConfig(), progress=say)
    except ObjscanError as exc:
        return {"error": {"code": exc.code, "message": exc.message, "detail": exc.detail},
                "views_used": order, "seconds": round(time.perf_counter() - t0, 4)}
    ply = model.write_ply(Path(out_dir) / "model.ply")
    figures = model.to_json()
    figures.update({"ply": str(ply.relative_to(out_dir)), "views_used": order,
                    "seconds": round(time.perf_counter() - t0, 4)})
    report.setdefault("summary", {})["seconds_total"] = round(
        float(report.get("summary", {}).get("total_s", 0.0)) + figures["seconds"], 3)
    return figures


def _ground_truth(result: ViewResult, frames: list) -> dict[str, Any] | None:
    errs = relative_pose_errors(result, frames)
    if not errs:
        return None
    prior = prior_pose_errors(frames) or []
    return {
        "max_trans_err_mm": round(max(e[0] for e in errs), 4),
        "max_rot_err_deg": round(max(e[1] for e in errs), 5),
        "prior_max_trans_err_mm": round(max((e[0] for e in prior), default=0.0), 4),
        "prior_max_rot_err_deg": round(max((e[1] for e in prior), default=0.0), 5),
        "relative_to": "scan 0",
    }


def _summary(views: list[dict[str, Any]], total_s: float) -> dict[str, Any]:
    ok = [v for v in views if "error" not in v]
    gts = [v["ground_truth"] for v in ok if "ground_truth" in v]
    s = {
        "views": len(views),
        "views_ok": len(ok),
        "views_failed": [v["index"] for v in views if "error" in v],
        "total_s": round(total_s, 3),
        "s_per_view_mean": round(float(np.mean([v["seconds"] for v in views])), 4) if views else 0.0,
        "paths": sorted({s["path"] for v in ok for s in v["scans"]}),
    }
    if gts:
        s["max_trans_err_mm"] = max(g["max_trans_err_mm"] for g in gts)
        s["max_rot_err_deg"] = max(g["max_rot_err_deg"] for g in gts)
    return s
