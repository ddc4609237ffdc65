"""What the export reads from a session folder: the point model, the table, the registered camera poses.

Everything comes from files the acquisition already wrote (docs/session-folder.md): ``model.ply`` (points in
view 0's ``base``), ``report.json`` (``model_figures.T_model_view``: view k's ``base`` into the model),
``view_KK/view.json`` (the registered scan camera poses and the table plane of view k) and the scans'
RGB-D frames. A scan's camera pose in the model is ``T_model_view[k] @ scan_poses[j]``: the pose static
registration corrected, moved by the turn dynamic registration measured.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from common.errors import ObjscanError
from common.messages import RGBDFrame
from common.session_folder import MODEL_FILE, REPORT_FILE, read_scan, read_session, view_dir
from services.export.errors import ExportInputError
from services.registration.api import read_ply


@dataclass
class PosedFrame:
    """One RGB-D scan with its registered camera pose in the model frame (view 0's ``base``)."""

    view: int
    scan: int
    frame: RGBDFrame
    T_model_camera: np.ndarray


@dataclass
class SessionModel:
    """The session's point model, its table and (lazily) its posed frames."""

    path: Path
    xyz: np.ndarray  # (N, 3) float64, model frame
    rgb: np.ndarray | None  # (N, 3) uint8
    normals: np.ndarray | None  # (N, 3) float64
    table_normal: np.ndarray  # unit, up, model frame
    table_offset: float  # normal . p + offset = 0
    T_model_view: dict[int, np.ndarray]
    scan_poses: dict[int, np.ndarray]  # view -> (S, 4, 4) registered T_base_camera of its scans
    data: dict[str, Any] = field(default_factory=dict)  # session.json

    def frames(self) -> list[PosedFrame]:
        """Every complete scan of every view fused into the model, posed in the model frame."""
        info = read_session(self.path)
        out = []
        for k in sorted(self.T_model_view):
            poses = self.scan_poses.get(k)
            for j in info.scans(k):
                if poses is None or j >= len(poses):
                    continue
                out.append(PosedFrame(k, j, read_scan(self.path, k, j), self.T_model_view[k] @ poses[j]))
        return out

    def ground_truth_pose(self) -> np.ndarray | None:
        """The true object pose in ``base`` at view 0 (twin sessions only), for the figures against the truth."""
        from services.sim.ground_truth import recorded_pose

        return recorded_pose(self.path)


def load_session_model(session: str | Path) -> SessionModel:
    """Read the model, the table of view 0 and the registered poses; a typed error names what is missing."""
    path = Path(session)
    try:
        info = read_session(path)
    except ObjscanError as exc:
        raise ExportInputError(exc.message, code="bad_session", detail={"session": str(path)}) from None
    if not (path / MODEL_FILE).is_file():
        raise ExportInputError(f"{path} holds no model.ply (did the acquisition finish?)", code="no_model",
                               detail={"session": str(path)})
    cloud = read_ply(path / MODEL_FILE)
    report = _json(path / REPORT_FILE) or {}
    figures = report.get("model_figures") or report.get("model") or {}
    poses = figures.get("T_model_view") if isinstance(figures, dict) else None
    used = figures.get("views_used") if isinstance(figures, dict) else None
    indices = [int(v["index"]) for v in info.views]
    T_model_view: dict[int, np.ndarray] = {}
    if isinstance(poses, list) and poses:
        order = [int(k) for k in used] if isinstance(used, list) and len(used) == len(poses) else indices
        left_out = set(figures.get("views_left_out") or [])
        for k, T in zip(order, poses, strict=False):
            if k not in left_out:
                T_model_view[k] = np.asarray(T, dtype=np.float64).reshape(4, 4)
    scan_poses: dict[int, np.ndarray] = {}
    table = None
    for k in indices:
        view = _json(view_dir(path, k) / "view.json")
        if not view:
            continue
        scan_poses[k] = np.asarray(view.get("scan_poses", []), dtype=np.float64).reshape(-1, 4, 4)
        if table is None and k == min(indices):
            table = view.get("table")
    if table is None:
        raise ExportInputError(f"{path} has no table plane for its first view (view_00/view.json)",
                               code="no_table", detail={"session": str(path)})
    normal = np.asarray(table["normal"], dtype=np.float64)
    normal /= np.linalg.norm(normal)
    return SessionModel(path=path, xyz=np.asarray(cloud.xyz, dtype=np.float64),
                        rgb=None if cloud.rgb is None else np.asarray(cloud.rgb, dtype=np.uint8),
                        normals=None if cloud.normals is None else np.asarray(cloud.normals, dtype=np.float64),
                        table_normal=normal, table_offset=float(table["offset"]), T_model_view=T_model_view,
                        scan_poses=scan_poses, data=info.data)


def _json(p: Path) -> Any:
    try:
        return json.loads(p.read_text()) if p.is_file() else None
    except (OSError, json.JSONDecodeError) as exc:
        raise ExportInputError(f"{p} is not valid JSON: {exc}", code="bad_session", detail={"path": str(p)}) from None
