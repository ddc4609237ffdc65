"""Table-plane segmentation: RANSAC, a least-squares refit, and the normal turned up.

The paper keeps the table's normal and approximate centre for the grasp planner; the normal must point
from the table toward the object (toward the cameras, which always look down on the table), whatever
sign RANSAC happens to return.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from common.messages import Plane

from .errors import NoTableError


@dataclass
class TableFit:
    plane: Plane
    inliers: np.ndarray  # bool mask over the points the plane was fitted to
    fraction: float  # inlier fraction of the cloud


def fit_plane_lsq(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Total-least-squares plane through ``points``: (unit normal, offset) with normal . p + offset = 0."""
    c = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - c, full_matrices=False)
    n = vt[2]
    return n, float(-n @ c)


def segment_table(
    points: np.ndarray,
    *,
    viewpoint: np.ndarray,
    distance: float,
    iterations: int,
    seed: int,
    voxel: float | None = None,
    min_fraction: float = 0.15,
    min_points: int = 200,
    expected_up: np.ndarray | None = None,
    max_tilt_deg: float = 25.0,
) -> TableFit:
    """Find the dominant plane of ``points`` and check it can be the table.

    RANSAC runs on a ``voxel`` down-sampled copy (it only needs to find the plane, not measure it), then the
    plane is refit by least squares on all points within ``distance``, twice, so noise at the edge of the
    RANSAC band does not tilt it. The normal is flipped to face ``viewpoint`` (a camera centre). Raises
    ``NoTableError`` when the plane is too small a part of the cloud, or tilted more than ``max_tilt_deg``
    from ``expected_up``.
    """
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < max(3, min_points):
        raise NoTableError("too few points to look for a table", detail={"points": len(pts)})
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    search = pcd.voxel_down_sample(voxel) if voxel else pcd
    if len(search.points) < 3:
        raise NoTableError("too few points to look for a table", detail={"points": len(pts)})
    o3d.utility.random.seed(int(seed))
    model, _ = search.segment_plane(distance_threshold=distance, ransac_n=3, num_iterations=iterations)
    n = np.asarray(model[:3], dtype=np.float64)
    d = float(model[3]) / np.linalg.norm(n)
    n = n / np.linalg.norm(n)
    for _ in range(2):
        inl = np.abs(pts @ n + d) < distance
        if inl.sum() < 3:
            break
        n_new, d_new = fit_plane_lsq(pts[inl])
        if n_new @ n < 0:
            n_new, d_new = -n_new, -d_new
        n, d = n_new, d_new
    inl = np.abs(pts @ n + d) < distance
    if float(np.asarray(viewpoint, dtype=np.float64) @ n + d) < 0:  # face the camera: up from the table
        n, d = -n, -d
    fraction = float(inl.mean())
    if inl.sum() < min_points or fraction < min_fraction:
        raise NoTableError(
            "no plane large enough to be the table",
            detail={"inliers": int(inl.sum()), "fraction": round(fraction, 3), "min_fraction": min_fraction},
        )
    if expected_up is not None:
        up = np.asarray(expected_up, dtype=np.float64)
        tilt = float(np.degrees(np.arccos(np.clip(n @ up / np.linalg.norm(up), -1.0, 1.0))))
        if tilt > max_tilt_deg:
            raise NoTableError(
                "the dominant plane is not horizontal, so it is not the table",
                detail={"tilt_deg": round(tilt, 1), "max_tilt_deg": max_tilt_deg},
            )
    centre = pts[inl].mean(axis=0)
    return TableFit(plane=Plane(normal=n, offset=d, center=centre), inliers=inl, fraction=fraction)
