"""``objscan bench acquisition``: a whole simulated acquisition through every service, timed and scored.

Runs the main job (``objscan scan``) on the twin: 12 views of a HOPE object (``quick``: 4 views) under the
``realistic`` profile (the benchmarks' default twin; ``$OBJSCAN_BENCH_PROFILE`` names another, e.g.
``robot-turned`` as measured before), and reports the time, the grasp attempts and re-scans it took, and the model's
accuracy against the ground-truth mesh (Chamfer, one-sided accuracy and completeness, F-score).

The twin's grasp/set-down model is ``$OBJSCAN_BENCH_PHYSICS`` (``mujoco``, the default as for ``objscan
scan``, or ``geometric``). ``$OBJSCAN_BENCH_OBJECTS`` (comma-separated HOPE names or mesh paths) scans
several objects one after the other: the figures then sit under ``objects`` (one entry each). With
``$OBJSCAN_BENCH_SESSIONS`` (comma-separated finished session folders, e.g. of ``objscan scan``) nothing
is scanned: those sessions are scored from their ``report.json`` and ``journal.json``.

One object (the default): scanned twice in the same run, with the incremental model (pair registrations of
every configuration the automatic choice may run, while the arm turns, the default) and without it (every
pair at the end, the old path) as the baseline. The
headline figure is ``model_ready_s_after_last_view``: from the last view's last scan saved to the model saved
(target <= 5 s). The machine may be shared: each acquisition records the load average before and after
and the CPU seconds of the services it started (``cpu_s``), beside the wall times.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any

from common import keys
from common.client import request_sync
from common.launcher import ServiceGroup
from common.messages import Request
from common.session_folder import REPORT_FILE
from services.cell import cell_specs

PROFILE = "realistic"


def _children_cpu() -> float:
    import resource

    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def acquire(out: Path, *, object_name: str, views: int, profile: str, seed: int, log_dir: Path,
            physics: str = "mujoco", incremental: bool = True) -> dict[str, Any]:
    load_before, c0 = os.getloadavg(), _children_cpu()
    with ServiceGroup(log_dir=log_dir) as group:
        # the orchestrator writes sessions only under its --sessions root: the session's parent folder
        group.launch(cell_specs(extra_args={"orchestrator": ["--sessions", str(Path(out).resolve().parent)]}),
                     timeout=300)
        t0 = time.perf_counter()
        request_sync(group.session, keys.orchestrator(keys.DEFAULT_ROBOT, "run"), Request(params={
            "out": str(out), "config": {"object": object_name, "views": views, "profile": profile, "seed": seed,
                                        "physics": physics, "incremental": incremental}}),
            timeout=30)
        while True:
            s = request_sync(group.session, keys.orchestrator(keys.DEFAULT_ROBOT, "status"), timeout=10).info
            if s.get("status") in ("done", "failed", "stopped"):
                break
            time.sleep(1.0)
        seconds = time.perf_counter() - t0
    return {**score_session(out, seconds=seconds, status=s.get("status"), error=s.get("last_error")),
            "cpu_s": round(_children_cpu() - c0, 1), "load_average_before": [round(v, 2) for v in load_before],
            "load_average_after": [round(v, 2) for v in os.getloadavg()]}


def true_turns(out: Path) -> dict[str, Any]:
    """The turns the object really made between consecutive views (sim ground truth in each view's first
    scan): |yaw change| per step, and the largest tilt from upright seen (a topple shows here)."""
    import numpy as np

    from services.sim.world import yaw_of

    poses = []
    for k in range(100):
        meta = out / f"view_{k:02d}" / "scan_0" / "meta.json"
        if not meta.is_file():
            break
        T = json.loads(meta.read_text()).get("T_base_object_true")
        if T is None:
            return {}
        poses.append(np.asarray(T, dtype=float).reshape(4, 4))
    if len(poses) < 2:
        return {}
    steps = [abs((np.degrees(yaw_of(b) - yaw_of(a)) + 180.0) % 360.0 - 180.0) for a, b in zip(poses, poses[1:])]
    tilt = max(float(np.degrees(np.arccos(np.clip(T[2, 2], -1, 1)))) for T in poses)
    return {"turn_deg_mean": round(float(np.mean(steps)), 2), "turn_deg_min": round(float(min(steps)), 2),
            "turn_deg_max": round(float(max(steps)), 2), "max_tilt_deg": round(tilt, 2)}


def score_session(out: Path, *, seconds: float | None = None, status: str | None = None,
                  error: dict | None = None) -> dict[str, Any]:
    """The figures of one finished session folder (its report.json and journal.json)."""
    report = json.loads((out / REPORT_FILE).read_text()) if (out / REPORT_FILE).is_file() else {}
    journal = json.loads((out / "journal.json").read_text())
    acc = report.get("accuracy", {})
    model = report.get("model_figures", {})
    cfg = journal.get("config", {})
    views = int(cfg.get("views", 12))
    if seconds is None:
        seconds = float(sum((journal.get("timings_s") or {}).values())) or 0.0
    return {"object": cfg.get("object"), "views": views, "profile": cfg.get("profile"),
            "physics": cfg.get("physics", "geometric"), "status": status or journal.get("status"),
            "topple_restarts": journal.get("topple_restarts", 0), "incremental": cfg.get("incremental", True),
            "model_ready_s_after_last_view": report.get("model_ready_s_after_last_view"),
            "dynamic_s": model.get("timings", {}).get("total_s"), "pairs": model.get("timings", {}).get("pairs"),
            "seconds_total": round(seconds, 1), "seconds_per_view": round(seconds / views, 1),
            "grasp_attempts": journal["counters"]["grasp_attempts"], "rescans": journal["counters"]["rescans"],
            "regrasps": journal["counters"].get("regrasps", 0),  # relocated set-downs (orchestrator/regrasp.py)
            **{k: acc.get(k) for k in ("chamfer_mm", "accuracy_mm", "completeness_mm", "fscore_2mm", "fscore_5mm")},
            "unaligned_chamfer_mm": acc.get("unaligned", {}).get("chamfer_mm"),
            "configuration": model.get("configuration"),
            "true_turns": true_turns(out),
            "timings_s": journal.get("timings_s"), "session": str(out), "error": error or journal.get("error")}


def run(quick: bool = False) -> dict[str, Any]:
    sessions = [p for p in os.environ.get("OBJSCAN_BENCH_SESSIONS", "").split(",") if p.strip()]
    if sessions:
        return {"objects": [score_session(Path(p.strip())) for p in sessions]}
    physics = os.environ.get("OBJSCAN_BENCH_PHYSICS", "mujoco")
    profile = os.environ.get("OBJSCAN_BENCH_PROFILE", "").strip() or PROFILE
    names = [n.strip() for n in os.environ.get("OBJSCAN_BENCH_OBJECTS", "milk").split(",") if n.strip()]
    root = Path(tempfile.mkdtemp(prefix="objscan-bench-acq-"))
    views = 4 if quick else 12
    if len(names) > 1:
        return {"objects": [acquire(root / f"session_{i}", object_name=name, views=views, profile=profile,
                                    seed=1, log_dir=root / f"logs_{i}", physics=physics)
                            for i, name in enumerate(names)]}
    runs = {}
    for variant, incremental in (("incremental", True), ("end_of_run", False)):
        runs[variant] = acquire(root / variant, object_name=names[0], views=views, profile=profile, seed=1,
                                log_dir=root / f"logs-{variant}", physics=physics, incremental=incremental)
    inc, base = runs["incremental"], runs["end_of_run"]
    return {**inc, "model_ready_s_after_last_view_end_of_run": base["model_ready_s_after_last_view"],
            "target_s": 5.0, "seconds_total_end_of_run": base["seconds_total"],
            "chamfer_mm_end_of_run": base["chamfer_mm"], "profile": profile, "runs": runs}
