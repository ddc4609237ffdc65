"""Which points a scan saw: projection into its depth image, agreement within a tolerance.

One test for the steps that need it: the texture takes a triangle's colours from a scan that saw it, and
the surface orients each model point's normal towards the scans that saw it (``orient.py``). A point counts
as seen when it projects inside the image, in front of the camera, and the scan's depth there agrees with
its own depth within ``VISIBLE_TOL_M`` (so a point hidden behind another surface is not).
"""

from __future__ import annotations

import numpy as np

from common.geometry import invert, transform_points
from services.export.inputs import PosedFrame

#: A point counts as seen by a scan when the scan's depth at its pixel agrees within this (m).
VISIBLE_TOL_M = 0.004
#: Nearer than this (m) to the camera is in front of the lens, not in the scan.
MIN_DEPTH_M = 0.05


def camera_in_object(pf: PosedFrame, T_object_model: np.ndarray) -> np.ndarray:
    """The scan's camera pose in the object frame (``T_object_camera``)."""
    return T_object_model @ pf.T_model_camera


def seen_by(points_object: np.ndarray, pf: PosedFrame, T_object_camera: np.ndarray,
            tol_m: float = VISIBLE_TOL_M) -> np.ndarray:
    """Mask of the object-frame ``points_object`` (N, 3) that the scan ``pf`` saw."""
    p = transform_points(invert(T_object_camera), points_object)
    z = p[:, 2]
    K = pf.frame.intrinsics
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.round(K.fx * p[:, 0] / z + K.cx)
        v = np.round(K.fy * p[:, 1] / z + K.cy)
    ok = (z > MIN_DEPTH_M) & (u >= 0) & (u < K.width) & (v >= 0) & (v < K.height)
    d = np.zeros(len(z))
    d[ok] = pf.frame.depth[v[ok].astype(np.int64), u[ok].astype(np.int64)] * pf.frame.depth_scale
    return ok & (d > 0) & (np.abs(d - z) < tol_m)
