"""The smallest-area rectangle around an object's footprint on the table.

One function because three parts need the same rectangle: the grasp planner's box fit (which faces the
pads can close on), the recovery's check of whether a tall object would topple if dropped (its footprint's
short side) and the export's object frame (the footprint's long side is x).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError


def min_area_rectangle(xy: np.ndarray, max_hull_input: int = 2000, hull_spacing: float = 0.002
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smallest-area enclosing rectangle of 2-D points (rotating calipers over the convex hull edges).

    Returns (centre (2,), axes (2, 2) as columns, full side lengths (2,)). One side of the optimal
    rectangle is collinear with a hull edge, so trying every hull edge direction is exact. A round
    object puts thousands of points on its hull, so the hull is taken of an evenly strided subset of at
    most ``max_hull_input`` points and then resampled to vertices ``hull_spacing`` apart along its
    perimeter; the final extents use every point, so only the direction is approximate.
    """
    xy = np.asarray(xy, float)
    thin = xy[:: max(1, len(xy) // max_hull_input)]
    try:
        hull_pts = thin[ConvexHull(thin).vertices]  # counter-clockwise in 2-D
    except (QhullError, ValueError):
        hull_pts = thin  # collinear or too few points: the direction search below still works
    if len(hull_pts) > 8:
        seg = np.linalg.norm(np.diff(hull_pts, axis=0), axis=1)
        arc = np.concatenate([[0.0], np.cumsum(seg)])
        _, keep = np.unique(np.floor(arc / hull_spacing), return_index=True)
        hull_pts = hull_pts[keep]
    edges = np.diff(np.vstack([hull_pts, hull_pts[:1]]), axis=0)
    edges = edges[np.linalg.norm(edges, axis=1) > 1e-12]
    if len(edges) == 0:
        return xy.mean(axis=0), np.eye(2), np.zeros(2)
    angles = np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2)
    c, s = np.cos(angles), np.sin(angles)
    # project the hull points on (u, v) for every candidate angle at once
    u = hull_pts[:, 0:1] * c + hull_pts[:, 1:2] * s  # (H, A)
    v = -hull_pts[:, 0:1] * s + hull_pts[:, 1:2] * c
    k = int(np.argmin((u.max(axis=0) - u.min(axis=0)) * (v.max(axis=0) - v.min(axis=0))))
    axes = np.array([[c[k], -s[k]], [s[k], c[k]]])
    uv = xy @ axes  # exact extents from every point
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    return axes @ (0.5 * (lo + hi)), axes, hi - lo
