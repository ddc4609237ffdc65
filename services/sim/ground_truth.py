"""The twin's ground truth of a captured frame: the true object surface where the object stood.

A frame the twin renders records which mesh it shows (``object_model``: source, scale, up axis) and where the
object stood (``T_base_object_true``); both survive in a session folder's ``meta.json``. A report or an export
of a twin session compares the model against this surface (docs/report.md); nothing on a real cell has it.
"""

from __future__ import annotations

import numpy as np

from common.messages import RGBDFrame
from services.sim.catalogue import load_object
from services.sim.errors import SimInputError


def true_object_points(frame: RGBDFrame, n: int = 50000, seed: int = 0, *, colors: bool = False
                       ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Ground-truth surface samples of the object in ``base`` as it stood when ``frame`` was captured
    (from the frame's ``object_model`` and ``T_base_object_true``; works on frames read back from a
    session folder too). With ``colors``: (points, uint8 colours). For evaluation only."""
    meta = frame.meta or {}
    model, T = meta.get("object_model"), meta.get("T_base_object_true")
    if not model or T is None:
        raise SimInputError("frame carries no ground truth (not from the sim?)", code="bad_value")
    obj = load_object(model["source"] or model["name"], scale=model["scale"], up_axis=model["up_axis"])
    T = np.asarray(T, dtype=np.float64).reshape(4, 4)
    pts, rgb = obj.gt_colored_points(n, seed)
    pts = pts @ T[:3, :3].T + T[:3, 3]
    return (pts, rgb) if colors else pts
