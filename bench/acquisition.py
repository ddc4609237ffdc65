"""``objscan bench acquisition``: a whole simulated acquisition through every service, timed and scored.

Runs the main job (``objscan scan``) on the twin: 12 views of a HOPE object (``quick``: 4 views) under the
``robot-turned`` profile, and reports the time, the grasp attempts and re-scans it took, and the model's
accuracy against the ground-truth mesh (Chamfer, one-sided accuracy and completeness, F-score).

Twice, in the same run: with the incremental model (pair registrations while the arm turns, the default)
and without it (every pair at the end, the old path) as the baseline. The headline figure is
``model_ready_s_after_last_view``: from the last view's last scan saved to the model saved (target <= 5 s).
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path
from typing import Any

from common import keys
from common.client import request_sync
from common.launcher import ServiceGroup
from common.messages import Request
from services.cli.cells import cell_specs


def acquire(out: Path, *, object_name: str, views: int, profile: str, seed: int, log_dir: Path,
            incremental: bool = True) -> dict[str, Any]:
    with ServiceGroup(log_dir=log_dir) as group:
        group.launch(cell_specs(), timeout=300)
        t0 = time.perf_counter()
        request_sync(group.session, keys.orchestrator(keys.DEFAULT_ROBOT, "run"), Request(params={
            "out": str(out), "config": {"object": object_name, "views": views, "profile": profile, "seed": seed,
                                         "incremental": incremental}}),
            timeout=30)
        while True:
            s = request_sync(group.session, keys.orchestrator(keys.DEFAULT_ROBOT, "status"), timeout=10).info
            if s.get("status") in ("done", "failed", "stopped"):
                break
            time.sleep(1.0)
        seconds = time.perf_counter() - t0
    report = json.loads((out / "report.json").read_text()) if (out / "report.json").is_file() else {}
    journal = json.loads((out / "journal.json").read_text())
    acc = report.get("accuracy", {})
    model = report.get("model_figures", {})
    return {"object": object_name, "views": views, "profile": profile, "status": s.get("status"),
            "incremental": incremental, "model_ready_s_after_last_view": report.get("model_ready_s_after_last_view"),
            "dynamic_s": model.get("timings", {}).get("total_s"), "pairs": model.get("timings", {}).get("pairs"),
            "seconds_total": round(seconds, 1), "seconds_per_view": round(seconds / views, 1),
            "grasp_attempts": journal["counters"]["grasp_attempts"], "rescans": journal["counters"]["rescans"],
            **{k: acc.get(k) for k in ("chamfer_mm", "accuracy_mm", "completeness_mm", "fscore_2mm", "fscore_5mm")},
            "unaligned_chamfer_mm": acc.get("unaligned", {}).get("chamfer_mm"),
            "configuration": report.get("model_figures", {}).get("configuration"),
            "timings_s": journal.get("timings_s"), "session": str(out), "error": s.get("last_error")}


def run(quick: bool = False) -> dict[str, Any]:
    root = Path(tempfile.mkdtemp(prefix="objscan-bench-acq-"))
    runs = {}
    for name, incremental in (("incremental", True), ("end_of_run", False)):
        runs[name] = acquire(root / name, object_name="milk", views=4 if quick else 12, profile="robot-turned",
                             seed=1, log_dir=root / f"logs-{name}", incremental=incremental)
    inc, base = runs["incremental"], runs["end_of_run"]
    return {"model_ready_s_after_last_view": inc["model_ready_s_after_last_view"],
            "model_ready_s_after_last_view_end_of_run": base["model_ready_s_after_last_view"],
            "target_s": 5.0, "seconds_total": inc["seconds_total"], "seconds_total_end_of_run": base["seconds_total"],
            "chamfer_mm": inc["chamfer_mm"], "chamfer_mm_end_of_run": base["chamfer_mm"], **runs}
