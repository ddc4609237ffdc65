"""Everything a report shows, read from a finished (or failed) acquisition folder.

Readers are lenient on purpose: a report of a failed run is most useful exactly when files are missing,
so each part that is absent is ``None`` / empty and the page says so. Only a folder that is not a session
at all is an error. Layouts read: the orchestrator's (``services/session_store.py``) and, for views,
``objscan reconstruct``'s ``views/view_KK.ply`` when the output went into the session folder.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from common.messages import PointCloud
from common.session_folder import MODEL_FILE, REPORT_FILE, SessionFolderError, read_scan_dir, read_session, scan_dir
from services.registration.api import CloudError, read_ply
from services.report.errors import ReportError


@dataclass
class ViewData:
    """One view: its complete scans, isolated object, grasp plans and the grasp that turned it."""

    index: int
    commanded_turn_deg: float
    scan_dirs: list[Path]
    object_cloud: PointCloud | None
    figures: dict[str, Any]
    grasp_plans: dict[str, dict[str, Any]]  # mode -> grasps_<mode>.json
    chosen: dict[str, Any] | None  # the journal's "turned" decision of this view
    decisions: list[dict[str, Any]]


@dataclass
class SessionData:
    """A session folder, parsed."""

    path: Path
    info: dict[str, Any]
    journal: dict[str, Any]
    report: dict[str, Any]
    views: list[ViewData]
    model: PointCloud | None
    model_figures: dict[str, Any]
    accuracy: dict[str, Any] | None
    timings_s: dict[str, float]
    decisions: list[dict[str, Any]] = field(default_factory=list)

    @property
    def object_name(self) -> str:
        cfg = self.info.get("config") or self.journal.get("config") or {}
        return str(self.info.get("object") or cfg.get("object") or self.report.get("object") or "unknown object")

    @property
    def simulated(self) -> bool:
        return bool(self.info.get("simulated") or self.journal.get("simulated") or self.info.get("source") == "sim")


def load_session(session_dir: str | Path) -> SessionData:
    """Parse ``session_dir``; raises ``ReportError`` (``bad_session``) when it is not a session folder."""
    path = Path(session_dir)
    try:
        session = read_session(path)
    except SessionFolderError as exc:
        raise ReportError(exc.message, code="bad_session", detail={"session": str(path)}) from None
    journal = _json(path / "journal.json")
    report = _json(path / REPORT_FILE)
    decisions = report.get("decisions") or journal.get("decisions") or []
    views = [_view(path, v, decisions) for v in session.views]
    figures = report.get("model_figures")
    if figures is None and isinstance(report.get("model"), dict):
        figures = report["model"]  # objscan reconstruct's report.json
    model = _cloud(path / MODEL_FILE)
    return SessionData(path=path, info=session.data, journal=journal, report=report, views=views, model=model,
                       model_figures=figures or {}, accuracy=report.get("accuracy"),
                       timings_s=report.get("timings_s") or journal.get("timings_s") or {}, decisions=decisions)


def first_frame_meta(session: SessionData) -> Any:
    """The RGBDFrame of view 0 scan 0 (ground truth lives in its meta), or None."""
    for view in session.views:
        for d in view.scan_dirs:
            try:
                return read_scan_dir(d)
            except SessionFolderError:
                continue
    return None


def _view(path: Path, entry: dict[str, Any], decisions: list[dict[str, Any]]) -> ViewData:
    k = int(entry["index"])
    vdir = path / f"view_{k:02d}"
    scans = []
    j = 0
    while scan_dir(path, k, j).is_dir() or j < 3:
        d = scan_dir(path, k, j)
        if (d / "meta.json").is_file() and (d / "color.png").is_file():
            scans.append(d)
        j += 1
        if j > 50:
            break
    cloud = _cloud(vdir / "object.ply") or _cloud(path / "views" / f"view_{k:02d}.ply")
    view_json = _json(vdir / "view.json")
    plans = {p.stem.removeprefix("grasps_"): _json(p) for p in sorted(vdir.glob("grasps_*.json"))}
    mine = [d for d in decisions if int(d.get("view", -99)) == k]
    chosen = next((d for d in reversed(mine) if d.get("what") == "turned"), None)
    return ViewData(index=k, commanded_turn_deg=float(entry.get("commanded_turn_deg", 0.0)), scan_dirs=scans,
                    object_cloud=cloud, figures=view_json.get("figures", {}), grasp_plans=plans, chosen=chosen,
                    decisions=mine)


def _cloud(path: Path) -> PointCloud | None:
    if not path.is_file():
        return None
    try:
        return read_ply(path)
    except CloudError:
        return None


def _json(path: Path) -> dict[str, Any]:
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return {}
    return data if isinstance(data, dict) else {}


def ground_truth_points(session: SessionData, n: int = 60000) -> np.ndarray | None:
    """The true object surface in ``base`` as it stood in view 0 (the model's frame), for a simulated
    session whose first scan recorded its object model and true pose; None otherwise."""
    frame = first_frame_meta(session)
    if frame is None or "T_base_object_true" not in (frame.meta or {}):
        return None
    from services.sim.catalogue import load_object
    from services.sim.errors import SimInputError, SimObjectError
    from services.sim.ground_truth import posed_surface, true_object_points

    try:
        if frame.meta.get("object_model"):
            return np.asarray(true_object_points(frame, n=n))
        return posed_surface(load_object(session.object_name), frame.meta["T_base_object_true"], n)
    except (SimInputError, SimObjectError, OSError, KeyError, ValueError):
        return None
