"""The acquisition's ``report.json``: what the model is, how it was judged and what the run went through.

Its own module because writing the report is bookkeeping over a finished model, not a step of the state
machine: the machine hands over the journal, the model and (on a twin) its accuracy, and this module says
what the report holds. ``report.json``'s keys are read by the report page, the library and the tests, so
they stay as they are.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from common.api import ModelResult
from common.session_folder import REPORT_FILE, scan_dir
from services.orchestrator.journal import Journal
from services.session_store import SessionStore


def model_lateness_s(store: SessionStore, model_path: Path, last_view: int, last_scan: int) -> float | None:
    """Seconds from the last view's last scan saved to the model saved (how late the model comes after the
    arm's work ends); None when that scan's record is not in the session folder."""
    meta = scan_dir(store.path, last_view, last_scan) / "meta.json"
    if not meta.is_file():
        return None
    return round(model_path.stat().st_mtime - meta.stat().st_mtime, 2)


def model_section(j: Journal, result: ModelResult, turns_deg: list[float], incremental: bool) -> dict[str, Any]:
    """The report's account of the model: where it is, the dynamic stage's verdict and figures, the turns it
    was built from (the journal's model fields are set before)."""
    return {"model": j.model_path, "accepted": j.model_accepted, "why": j.model_why,
            "points": len(result.cloud), "model_figures": result.figures,
            "turns_commanded_deg": turns_deg, "incremental": incremental,
            "model_ready_s_after_last_view": j.model_ready_s_after_last_view}


def run_section(j: Journal, store: SessionStore, views: int) -> dict[str, Any]:
    """The report's account of the run: its config, counters, timings, every decision and each view's
    registration figures."""
    return {"session": str(store.path), "config": j.config, "counters": j.counters.to_dict(),
            "timings_s": j.timings_s, "seconds_total": round(time.time() - j.started, 2),
            "decisions": j.decisions,
            "views": [store.load_json(f"view_{k:02d}/view.json").get("figures", {}) for k in range(views)]}


def acquisition_report(j: Journal, store: SessionStore, result: ModelResult, turns_deg: list[float],
                       incremental: bool, accuracy: dict[str, Any] | None = None) -> dict[str, Any]:
    """The whole report of a finished acquisition of ``len(turns_deg)`` views (``accuracy`` on a twin)."""
    report = model_section(j, result, turns_deg, incremental)
    if accuracy is not None:
        report["accuracy"] = accuracy
    return {**report, **run_section(j, store, len(turns_deg))}


def write_report(store: SessionStore, report: dict[str, Any]) -> Path:
    """Write ``report.json`` atomically into the session folder."""
    store.save_json(REPORT_FILE, report)
    return store.path / REPORT_FILE
