"""``objscan reconstruct``: the offline pipeline over a session folder.

Reads the session (``common.session_folder``), registers each view's scans and isolates the object
(``services.registration.static``), writes ``OUT/views/view_KK.ply`` (object cloud in ``base``: xyz, rgb,
normals) and ``OUT/report.json`` (per-view figures, timings, ground-truth errors where the session has
truth). A view that fails (no table, no object, empty depth, ...) is reported with its error code and the
others go on. The dynamic stage (the 12 views into one model) plugs in at ``run_dynamic_stage``.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, ProcessPoolExecutor, ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from common.errors import ObjscanError
from common.pose_accuracy import session_pose_accuracy
from common.session_folder import MODEL_FILE, REPORT_FILE, atomic_write_json, read_scan, read_session
from services.registration.api import session_dynamic_config
from services.registration.cloud import write_ply
from services.registration.dynamic.turns import imported_turn_misses
from services.registration.dynamic.views import view_from_static
from services.registration.static import StaticConfig, StaticViewResult, register_view
from services.registration.static.pose_errors import prior_pose_errors, relative_pose_errors
from services.registration.warm_import import WarmImport

if TYPE_CHECKING:
    from services.registration.dynamic.model import MapPairs

#: What the dynamic stage imports (scikit-learn, more of SciPy): ~1.5 CPU-s, warmed up during the static stage
DYNAMIC_MODULES = ("services.registration.dynamic.model", "services.registration.dynamic.pair")

Progress = Callable[[dict[str, Any]], None]


def reconstruct(
    session_dir: str | Path,
    out_dir: str | Path,
    config: StaticConfig | None = None,
    progress: Progress | None = None,
    workers: int | None = None,
    dynamic: Any = None,
    threads: int | None = None,
) -> dict[str, Any]:
    """Run static registration on every view of ``session_dir``; write PLYs and ``report.json`` to ``out_dir``.

    ``progress`` (optional) is called with a small dict after each view (``stage``, ``view``, ``of``,
    ``status``, ``seconds``) so a CLI can show progress. ``workers`` local processes share the work
    (views, then the dynamic stage's pair jobs); ``1`` runs everything here. The default
    (``default_workers``) is one per core from 4 cores up and 1 below. Without worker processes, ``threads``
    threads of this process share the same work (default ``default_threads``: one per core; ``1``: serial):
    Open3D releases the GIL in its registration calls, and threads cost no start-up.
    The result does not depend on ``workers`` or ``threads``: each view and each pair job is computed by the
    same deterministic function wherever it runs (Open3D's one random generator is held per RANSAC call,
    ``cloud.o3d_seeded``). ``dynamic`` (a ``DynamicConfig``) overrides the dynamic
    stage's defaults. Returns the report (also written as JSON). Raises
    ``SessionFolderError`` only when the session itself is unreadable; per-view failures are in the report.
    """
    session = read_session(Path(session_dir))
    warm = WarmImport(DYNAMIC_MODULES)  # the dynamic stage's imports, while the static stage runs
    # the arm's pose accuracy the session states (else the conservative default): no scan correction beyond it
    # is fused
    accuracy, accuracy_source = session_pose_accuracy(session.data)
    cfg = (config or StaticConfig()).with_accuracy(accuracy if accuracy_source == "session" else None)
    out = Path(out_dir)
    (out / "views").mkdir(parents=True, exist_ok=True)
    remove_stale_results(out, session.path)
    t_start, cpu_start = time.perf_counter(), time.process_time()
    views_report: list[dict[str, Any]] = []
    results: dict[int, StaticViewResult] = {}
    indices = [int(entry["index"]) for entry in session.views]
    turns = {int(e["index"]): float(e.get("commanded_turn_deg", 0.0)) for e in session.views}
    n_workers = max(1, min(workers or default_workers(), len(indices)))
    n_threads = 1 if n_workers > 1 else max(1, min(threads or default_threads(), max(1, len(indices))))
    with _worker_pool(n_workers) as processes, _thread_pool(n_threads) as in_threads:
        pool: Executor | None = processes if processes is not None else in_threads
        jobs = [(session.path, index, session.scans(index), cfg) for index in indices]
        outcomes = pool.map(_register_one, jobs) if pool is not None else map(_register_one, jobs)
        for k, (index, item, result) in enumerate(outcomes):
            item = {"index": index, "commanded_turn_deg": turns[index], **item}
            if result is not None:
                ply = write_ply(out / "views" / f"view_{index:02d}.ply", result.object_cloud)
                item["ply"] = str(ply.relative_to(out))
                results[index] = result
            views_report.append(item)
            if progress is not None:
                progress({"stage": "static", "view": index, "of": len(indices), "done": k + 1,
                          "status": "failed" if result is None else "ok", "seconds": item["seconds"]})

        report: dict[str, Any] = {
            "session": str(session.path),
            "object": session.data.get("object"),
            "profile": cfg.profile,
            "config": cfg.as_dict(),
            "pose_accuracy": {**cfg.accuracy.to_dict(), "source": accuracy_source},
            "workers": n_workers,
            "threads": n_threads,
            "views": views_report,
            # the stage's process CPU without the warm-up import's (that is the dynamic stage's start-up)
            "summary": _summary(views_report, time.perf_counter() - t_start,
                                time.process_time() - cpu_start - warm.cpu_s()),
        }
        focal = session.data.get("import", {}).get("focal_calibration")
        if focal is not None:  # an imported sequence whose focal length was self-calibrated (importer/selfcal)
            report["focal_calibration"] = focal
        from services.registration.dynamic.pair import register_pair

        map_pairs = (lambda jobs: list(pool.map(register_pair, jobs))) if pool is not None else None
        report["model"] = run_dynamic_stage(results, session, out, report, progress, map_pairs=map_pairs,
                                            config=dynamic)
    atomic_write_json(out / REPORT_FILE, report)
    return report


def remove_stale_results(out: Path, session_path: Path) -> list[Path]:
    """Remove the result files an earlier run left in ``out`` (``model.ply``, ``views/view_KK.ply``).

    Why: a run whose dynamic stage fails writes no model, and an old ``model.ply`` beside the new report would
    be read (evaluated, added to a library) as this run's. Not done when ``out`` is the session folder itself:
    there ``model.ply`` is the acquisition's own model, acquired data that a failed re-run must not lose (the
    new model replaces it atomically when the run succeeds).
    """
    if out.resolve() == Path(session_path).resolve():
        return []
    stale = [out / MODEL_FILE, *sorted((out / "views").glob("view_*.ply"))]
    removed = []
    for path in stale:
        if path.is_file():
            path.unlink()
            removed.append(path)
    return removed


def default_workers() -> int:
    """Worker processes worth spawning here.

    A spawned worker spends ~5 CPU-s importing open3d, scikit-learn, scipy and numba before it works, and a
    12-view reconstruct is ~20 CPU-s in all: on 2-3 cores the import cost eats the gain (measured 42-54 s in
    one process vs 71-88 s with two workers on a loaded 2-core box); from 4 cores up each worker's share of
    the work outweighs its start-up.
    """
    cores = os.cpu_count() or 1
    return cores if cores >= 4 else 1


def _register_one(
    job: tuple[Path, int, list[int], StaticConfig],
) -> tuple[int, dict[str, Any], StaticViewResult | None]:
    """One view's static registration (runs in a worker process): its report item and result, or the error."""
    session_path, index, scans, cfg = job
    t0 = time.perf_counter()
    item: dict[str, Any] = {}
    result: StaticViewResult | None = None
    try:
        if not scans:
            raise ObjscanError(f"view {index} has no complete scan", code="no_scans")
        frames = [read_scan(session_path, index, j) for j in scans]
        result = register_view(frames, cfg)
        item.update(result.to_json())
        item["scan_indices"] = scans
        gt = _ground_truth(result, frames)
        if gt:
            item["ground_truth"] = gt
    except ObjscanError as exc:
        item["error"] = {"code": exc.code, "message": exc.message, "detail": exc.detail}
        result = None
    item["seconds"] = round(time.perf_counter() - t0, 4)
    return index, item, result


def default_threads() -> int:
    """Threads worth running here when no worker processes are: one per core (at most 8).

    Views and pair jobs are independent and Open3D releases the GIL inside its calls, so on the 2-core
    machine two threads keep both cores busy without the ~5 CPU-s import a spawned worker pays.
    """
    return max(1, min(8, os.cpu_count() or 1))


@contextmanager
def _thread_pool(threads: int) -> Iterator[ThreadPoolExecutor | None]:
    """``threads`` threads of this process, or None for one (everything runs in the caller)."""
    if threads <= 1:
        yield None
        return
    with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="reconstruct") as pool:
        yield pool


@contextmanager
def _worker_pool(workers: int) -> Iterator[ProcessPoolExecutor | None]:
    """``workers`` spawned processes (not forked: open3d's OpenMP threads do not survive a fork), or None.

    Each worker runs single-threaded (``OMP_NUM_THREADS=1``): the processes already fill the cores, and
    OpenMP threads on top would only oversubscribe them.
    """
    if workers <= 1:
        yield None
        return
    env_before = os.environ.get("OMP_NUM_THREADS")
    os.environ["OMP_NUM_THREADS"] = "1"  # inherited by the spawned workers; this process is set up already
    try:
        with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            yield pool
    finally:
        if env_before is None:
            os.environ.pop("OMP_NUM_THREADS", None)
        else:
            os.environ["OMP_NUM_THREADS"] = env_before


# ==================================================================================================
# DYNAMIC STAGE -- the hook for dynamic registration (issue: dynamic scan registration, paper II-C).
# The dynamic-registration engineer replaces the body below with the call into
# ``services.registration.dynamic`` (not imported here yet): it receives every successful view's
# ``StaticViewResult`` (object cloud, table plane, object centre; keyed by view index), the session (for the
# commanded turns: ``session.commanded_turn_deg(k)``) and ``out_dir``; it writes the model (e.g.
# ``out_dir/model.ply``) and returns the JSON-able figures that go into ``report["model"]``.
# ==================================================================================================
def run_dynamic_stage(
    results: dict[int, StaticViewResult],
    session: Any,
    out_dir: Path,
    report: dict[str, Any],
    progress: Progress | None = None,
    map_pairs: MapPairs | None = None,
    config: Any = None,
) -> dict[str, Any] | None:
    """Dynamic registration of the views into one model: writes ``out_dir/model.ply``, returns its figures.

    Views are taken in index order with their commanded cumulative turns; fewer than 3 usable views
    (or a dynamic-stage error) is reported in the returned figures, not raised, like a failed view.
    ``report["accepted"]`` / ``report["why"]`` carry the model's verdict (``False`` when no model was built).
    The session's stated turn accuracy (``turn_accuracy_deg`` in ``session.json``, 1 sigma) sets the window
    beyond which a view correction is implausible (``outliers.py``).
    """
    from services.registration.dynamic.model import build_model

    t0 = time.perf_counter()
    order = sorted(results)
    views = [view_from_static(results[k], session.commanded_turn_deg(k), index=k) for k in order]
    say = (lambda stage, info: progress({"stage": f"dynamic:{stage}", **info})) if progress else None
    cfg = session_dynamic_config(session.data, config)
    try:
        model = build_model(views, cfg, map_pairs=map_pairs, progress=say)
    except ObjscanError as exc:
        report["accepted"], report["why"] = False, f"no model: {exc.message} [{exc.code}]"
        return {"error": {"code": exc.code, "message": exc.message, "detail": exc.detail},
                "views_used": order, "seconds": round(time.perf_counter() - t0, 4)}
    ply = model.write_ply(Path(out_dir) / MODEL_FILE)
    unsure = imported_turn_misses(session.data)  # an unsure import never yields an accepted model
    if unsure:
        model.accepted, model.why = False, "; ".join([m for m in (model.why,) if m] + unsure)
    report["accepted"], report["why"] = model.accepted, model.why
    figures = model.to_json()
    figures.update({"ply": str(ply.relative_to(out_dir)), "views_used": order, "turn_only": cfg.pair.turn_only,
                    "seconds": round(time.perf_counter() - t0, 4)})
    report.setdefault("summary", {})["seconds_total"] = round(
        float(report.get("summary", {}).get("total_s", 0.0)) + figures["seconds"], 3)
    return figures


def _ground_truth(result: StaticViewResult, frames: list) -> dict[str, Any] | None:
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


def _summary(views: list[dict[str, Any]], total_s: float, cpu_s: float) -> dict[str, Any]:
    """The static stage's figures. ``s_per_view_mean`` is each view's own wall time (in a thread it shares
    the cores); ``stage_s_per_view`` is the stage's wall over the views (its throughput, the issue's "static
    <= 1 s per view"); ``cpu_s`` the process CPU seconds of the stage (all threads), the load-independent one."""
    ok = [v for v in views if "error" not in v]
    gts = [v["ground_truth"] for v in ok if "ground_truth" in v]
    s = {
        "views": len(views),
        "views_ok": len(ok),
        "views_failed": [v["index"] for v in views if "error" in v],
        "total_s": round(total_s, 3),
        "s_per_view_mean": round(float(np.mean([v["seconds"] for v in views])), 4) if views else 0.0,
        "stage_s_per_view": round(total_s / len(views), 4) if views else 0.0,
        "cpu_s": round(cpu_s, 3),
        "paths": sorted({s["path"] for v in ok for s in v["scans"]}),
        # scans not fused (failed their check, or a correction beyond the arm's accuracy), per view
        "scans_left_out": {str(v["index"]): [e["index"] for e in v["scans_left_out"]]
                           for v in ok if v.get("scans_left_out")},
    }
    if gts:
        s["max_trans_err_mm"] = max(g["max_trans_err_mm"] for g in gts)
        s["max_rot_err_deg"] = max(g["max_rot_err_deg"] for g in gts)
    return s
