"""The footprint cap: the bottom nobody saw, closed by the table it stood on.

The object stands on the table through every view, so its bottom face is never seen, but the table plane
bounds it exactly: the bottom is the footprint (the outline of the object's lowest band, projected on the
table) at z = 0 of the object frame. Points laid on that footprint with normals pointing down give a
surface reconstruction the support it lacks, so the surface closes there instead of ballooning; any
vertex that still dips below the table is then put back on it (a plane cap, exact for an object that
stands flat).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from services.export.errors import ExportInputError

#: Height of the lowest band whose outline is the footprint (m): above the static stage's table cut (4 mm)
#: and low enough that a tapering object's outline is its base's.
FOOTPRINT_BAND_M = 0.012


def footprint_outline(xyz_object: np.ndarray, band_m: float = FOOTPRINT_BAND_M) -> np.ndarray:
    """The footprint polygon (K, 2), counter-clockwise, in the object frame's x-y plane.

    The convex hull of the lowest ``band_m`` of points (all points when that band is nearly empty): a
    concave footprint (an L-shaped base) is closed by its hull, one of the known limits (docs/export.md).
    """
    pts = np.asarray(xyz_object, dtype=np.float64)
    low = pts[pts[:, 2] < pts[:, 2].min() + band_m]
    if len(low) < 20:
        low = pts
    try:
        hull = ConvexHull(low[:, :2])
    except (QhullError, ValueError):
        raise ExportInputError("the model's footprint is degenerate", code="bad_model") from None
    return low[hull.vertices, :2]


def cap_points(outline: np.ndarray, spacing_m: float = 0.002) -> tuple[np.ndarray, np.ndarray]:
    """Points on the footprint at z = 0 every ``spacing_m`` (plus the outline) with normals (0, 0, -1)."""
    poly = np.asarray(outline, dtype=np.float64)
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0] + spacing_m, spacing_m),
                         np.arange(lo[1], hi[1] + spacing_m, spacing_m), indexing="ij")
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    inside = grid[inside_convex(poly, grid)]
    ring = []
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        n = max(int(np.ceil(np.linalg.norm(b - a) / spacing_m)), 1)
        t = np.arange(n)[:, None] / n
        ring.append(a + t * (b - a))
    xy = np.vstack([inside, *ring])
    xyz = np.column_stack([xy, np.zeros(len(xy))])
    normals = np.tile([0.0, 0.0, -1.0], (len(xy), 1))
    return xyz, normals


def inside_convex(poly: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Which of ``xy`` (N, 2) lie inside the convex counter-clockwise polygon ``poly`` (K, 2)."""
    inside = np.ones(len(xy), dtype=bool)
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        e = b - a
        inside &= e[0] * (xy[:, 1] - a[1]) - e[1] * (xy[:, 0] - a[0]) >= 0
    return inside


def flatten_bottom(vertices: np.ndarray) -> np.ndarray:
    """Vertices with every z below the table (z < 0) put on it: the cap is the table plane, exactly."""
    v = np.array(vertices, dtype=np.float64, copy=True)
    v[:, 2] = np.maximum(v[:, 2], 0.0)
    return v
