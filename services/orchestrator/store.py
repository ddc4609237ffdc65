"""The session folder as the orchestrator's memory: every step's inputs and outputs, before the next step.

Besides the shared layout (``session.json``, ``view_KK/scan_J/...``, see ``common/session_folder.py``) it
keeps:

- ``journal.json``: the state machine's position (state, view, attempts, counters) and every decision
  with its timing, rewritten atomically after each step: a killed orchestrator resumes from it;
- ``view_KK/view.json`` + ``view_KK/object.ply``: the registered view (static result);
- ``view_KK/grasps.json``: the plan and what was tried;
- ``model.ply`` and ``report.json`` at the end.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from common.api import ViewResult
from common.messages import Plane, PointCloud, RGBDFrame
from common.session_folder import (
    atomic_write_json,
    read_scan,
    scan_complete,
    view_dir,
    write_scan,
    write_session,
)
from services.registration.cloud import read_ply, write_ply

JOURNAL = "journal.json"


class SessionStore:
    """Reads and writes one acquisition's folder; all writes are atomic (temp file + rename)."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.path.mkdir(parents=True, exist_ok=True)

    # ----------------------------------------------------------------------------------- journal
    def load_journal(self) -> dict[str, Any] | None:
        p = self.path / JOURNAL
        return json.loads(p.read_text()) if p.is_file() else None

    def save_journal(self, journal: dict[str, Any]) -> None:
        journal["updated"] = time.time()
        atomic_write_json(self.path / JOURNAL, journal)

    def write_session_info(self, config: dict[str, Any], views_done: int, turns_deg: list[float],
                           extra: dict[str, Any] | None = None) -> None:
        """session.json in the shared layout: the views captured so far with their commanded turns."""
        data = {"version": 1, "object": config.get("object"), "profile": config.get("profile"),
                "seed": config.get("seed"), "config": config,
                "views": [{"index": k, "commanded_turn_deg": float(turns_deg[k])} for k in range(views_done)]}
        data.update(extra or {})
        write_session(self.path, data)

    # ----------------------------------------------------------------------------------- scans
    def has_scan(self, view: int, scan: int) -> bool:
        return scan_complete(self.path, view, scan)

    def save_scan(self, view: int, scan: int, frame: RGBDFrame, extra: dict[str, Any] | None = None) -> None:
        write_scan(self.path, view, scan, frame, extra)

    def load_scan(self, view: int, scan: int) -> RGBDFrame:
        return read_scan(self.path, view, scan)

    # ----------------------------------------------------------------------------------- views
    def save_view(self, result: ViewResult) -> None:
        d = view_dir(self.path, result.view)
        write_ply(d / "object.ply", result.cloud)
        atomic_write_json(d / "view.json", {
            "view": result.view, "center": result.center, "height": result.height,
            "table": {"normal": result.table.normal, "offset": result.table.offset, "center": result.table.center},
            "scan_poses": result.scan_poses, "figures": result.figures})

    def has_view(self, view: int) -> bool:
        d = view_dir(self.path, view)
        return (d / "view.json").is_file() and (d / "object.ply").is_file()

    def load_view(self, view: int) -> ViewResult:
        d = view_dir(self.path, view)
        meta = json.loads((d / "view.json").read_text())
        cloud: PointCloud = read_ply(d / "object.ply")
        t = meta["table"]
        table = Plane(normal=np.asarray(t["normal"], float), offset=float(t["offset"]),
                      center=np.asarray(t["center"], float))
        return ViewResult(view=int(meta["view"]), cloud=cloud, table=table, center=np.asarray(meta["center"], float),
                          height=float(meta["height"]), scan_poses=np.asarray(meta["scan_poses"], float),
                          figures=meta.get("figures", {}))

    def save_json(self, relative: str, data: Any) -> None:
        atomic_write_json(self.path / relative, data)

    def load_json(self, relative: str) -> Any:
        p = self.path / relative
        return json.loads(p.read_text()) if p.is_file() else None

    def save_model(self, cloud: PointCloud) -> Path:
        return write_ply(self.path / "model.ply", cloud)
