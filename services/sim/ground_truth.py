"""The twin's ground truth of a captured frame: the true object surface where the object stood.

A frame the twin renders records which mesh it shows (``object_model``: source, scale, up axis) and where the
object stood (``T_base_object_true``); both survive in a session folder's ``meta.json``. A report, an export or
``objscan reconstruct --gt`` of a twin session compares the model against this surface (docs/report.md), posed
as the object stood in view 0 (the model's frame); nothing on a real cell has it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from common.messages import RGBDFrame
from common.session_folder import scan_dir
from services.sim.catalogue import SimObject, load_object
from services.sim.errors import SimInputError


def recorded_pose(session: str | Path) -> np.ndarray | None:
    """The true object pose in ``base`` that view 0's first scan recorded (where the model's frame puts the
    object), or None for a session not from the twin."""
    try:
        T = json.loads((scan_dir(Path(session), 0, 0) / "meta.json").read_text()).get("T_base_object_true")
    except (OSError, json.JSONDecodeError, AttributeError):
        return None
    return None if T is None else np.asarray(T, dtype=np.float64).reshape(4, 4)


def posed(points: np.ndarray, T_base_object: np.ndarray) -> np.ndarray:
    """Object-frame points placed in ``base`` by ``T_base_object``."""
    T = np.asarray(T_base_object, dtype=np.float64).reshape(4, 4)
    return points @ T[:3, :3].T + T[:3, 3]


def posed_surface(obj: SimObject, T_base_object: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    """``n`` area-uniform true surface samples of ``obj`` where ``T_base_object`` placed it."""
    return posed(obj.gt_points(n, seed), T_base_object)


def true_object_points(frame: RGBDFrame, n: int = 50000, seed: int = 0, *, colors: bool = False
                       ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Ground-truth surface samples of the object in ``base`` as it stood when ``frame`` was captured
    (from the frame's ``object_model`` and ``T_base_object_true``; works on frames read back from a
    session folder too). With ``colors``: (points, uint8 colours)."""
    meta = frame.meta or {}
    model, T = meta.get("object_model"), meta.get("T_base_object_true")
    if not model or T is None:
        raise SimInputError("frame carries no ground truth (not from the sim?)", code="bad_value")
    obj = load_object(model["source"] or model["name"], scale=model["scale"], up_axis=model["up_axis"])
    pts, rgb = obj.gt_colored_points(n, seed)
    pts = posed(pts, T)
    return (pts, rgb) if colors else pts
