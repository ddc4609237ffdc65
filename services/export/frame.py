"""The object's own frame: where every exported file puts the object.

Origin at the centre of the object's footprint on the table, z up along the table normal, x along the
footprint's long side (y completes a right-handed frame). The footprint is the smallest-area rectangle
around the model projected on the table: for a box it is the box's base, for a can its bounding square.
A pose estimator or a simulator then finds the object standing at the origin, its long side on x, and the
session keeps ``T_base_object`` (this frame in the robot's ``base`` at view 0) to put it back.
"""

from __future__ import annotations

import numpy as np

from common.footprint import min_area_rectangle
from services.export.errors import ExportInputError


def object_frame(xyz: np.ndarray, table_normal: np.ndarray, table_offset: float) -> np.ndarray:
    """``T_model_object``: the object frame (see the module doc) in the frame the points are given in.

    ``table_normal``/``table_offset`` are the table plane ``n . p + d = 0`` with n pointing up.
    """
    pts = np.asarray(xyz, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[0] < 10:
        raise ExportInputError("the model has too few points for an object frame", code="bad_model",
                               detail={"points": int(pts.shape[0]) if pts.ndim == 2 else 0})
    z = np.asarray(table_normal, dtype=np.float64)
    z = z / np.linalg.norm(z)
    # any x in the table plane to start with; the footprint's long side replaces it
    seed = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x0 = seed - z * (seed @ z)
    x0 /= np.linalg.norm(x0)
    y0 = np.cross(z, x0)
    xy = np.column_stack([pts @ x0, pts @ y0])
    centre, axes, sides = min_area_rectangle(xy)
    if not sides.min() > 1e-9:
        raise ExportInputError("the model's footprint is degenerate (too few or collinear points)",
                               code="bad_model")
    long_dir = axes[:, int(np.argmax(sides))]
    x = long_dir[0] * x0 + long_dir[1] * y0
    x /= np.linalg.norm(x)
    # keep x pointing away from the robot (base +x) when the long side allows either sign: reproducible
    if x @ np.array([1.0, 0.0, 0.0]) < -1e-9 or (abs(x[0]) < 1e-9 and x[1] < 0):
        x = -x
    y = np.cross(z, x)
    origin_in_plane = centre[0] * x0 + centre[1] * y0
    # the point of the table plane under the footprint centre: n . p + d = 0
    origin = origin_in_plane - z * (origin_in_plane @ z + table_offset)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, origin
    return T
