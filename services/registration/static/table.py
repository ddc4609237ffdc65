"""Table-plane segmentation: several RANSAC planes, the table chosen by the prior, normal turned up.

The paper keeps the table's normal and approximate centre for the grasp planner; the normal must point
from the table toward the object (toward the cameras, which always look down on the table), whatever
sign RANSAC happens to return. The paper takes the biggest plane; in a real lab that is often a wall
(a camera looking across the table at the object), so the table is the plane that fits what we know: it
is level in ``base`` (within a tilt limit of the expected up), the object stands on it, and it lies near
the expected table height.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from common.messages import Plane
from services.registration.cloud import o3d_seeded

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


@dataclass
class PlaneCandidate:
    """One plane the search found, and whether the prior lets it be the table (``reason`` says why not)."""

    normal: np.ndarray  # unit, facing the viewpoint
    offset: float
    inliers: np.ndarray  # bool mask over the points
    tilt_deg: float | None  # from expected_up (None: no up known)
    seed_height: float | None  # m, the seed point above the plane (None: no seed)
    table_height: float | None  # m, the plane under the seed along expected_up (None: no up known)
    reason: str = ""  # empty when the plane qualifies as the table

    def summary(self) -> dict:
        return {
            "inliers": int(self.inliers.sum()),
            "fraction": round(float(self.inliers.mean()), 4),
            "tilt_deg": None if self.tilt_deg is None else round(self.tilt_deg, 1),
            "seed_height_m": None if self.seed_height is None else round(self.seed_height, 4),
            "table_height_m": None if self.table_height is None else round(self.table_height, 4),
            "rejected": self.reason or None,
        }


def _refit(pts: np.ndarray, n: np.ndarray, d: float, distance: float) -> tuple[np.ndarray, float]:
    """Least-squares refit on all points within ``distance``, twice (RANSAC's band edge would tilt it)."""
    for _ in range(2):
        inl = np.abs(pts @ n + d) < distance
        if inl.sum() < 3:
            break
        n_new, d_new = fit_plane_lsq(pts[inl])
        if n_new @ n < 0:
            n_new, d_new = -n_new, -d_new
        n, d = n_new, d_new
    return n, d


def find_planes(
    points: np.ndarray, *, distance: float, iterations: int, seed: int, voxel: float | None, max_planes: int,
    min_points: int,
) -> list[tuple[np.ndarray, float]]:
    """Up to ``max_planes`` planes, largest first: RANSAC on a coarse copy, each plane's points removed
    before the next search, each refit by least squares on the full cloud. (normal, offset) pairs."""
    pts = np.asarray(points, dtype=np.float64)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    search = pcd.voxel_down_sample(voxel) if voxel else pcd
    # a plane must hold min_points of the full cloud; on the coarse copy that is proportionally fewer
    min_search = max(3, int(min_points * len(search.points) / max(len(pts), 1)))
    planes = []
    for k in range(max_planes):
        if len(search.points) < max(3, min_search):
            break
        with o3d_seeded(int(seed) + k):
            model, inl = search.segment_plane(distance_threshold=distance, ransac_n=3, num_iterations=iterations)
        if len(inl) < min_search:
            break
        n = np.asarray(model[:3], dtype=np.float64)
        norm = np.linalg.norm(n)
        if not np.isfinite(norm) or norm < 1e-12:
            break
        planes.append(_refit(pts, n / norm, float(model[3]) / norm, distance))
        search = search.select_by_index(inl, invert=True)
    return planes


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
    seed_point: np.ndarray | None = None,
    max_seed_height: float | None = None,
    expected_height: float | None = None,
    height_tolerance: float = 0.08,
    max_planes: int = 1,
) -> TableFit:
    """Find the table among the planes of ``points``, by the prior, not by size alone.

    Up to ``max_planes`` planes are searched (``find_planes``), each normal turned to face ``viewpoint``
    (a camera centre), so it points up from the table. A plane is the table only if it holds
    ``min_points`` and ``min_fraction`` of the cloud, its normal lies within ``max_tilt_deg`` of
    ``expected_up``, the ``seed_point`` (where the camera looks: the object) is above it by at most
    ``max_seed_height``, and, with ``expected_height``, it lies within ``height_tolerance`` of that height
    along ``expected_up`` under the seed. Walls, shelves, the object's own faces and the far room are
    skipped; of the planes that qualify the largest wins (a grazing strip of table still beats the top of
    a box). Raises ``NoTableError`` when none qualifies, with every plane found and why it was rejected
    (``detail.planes``; ``detail.tilt_deg`` is the largest plane's tilt).
    """
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < max(3, min_points):
        raise NoTableError("too few points to look for a table", detail={"points": len(pts)})
    planes = find_planes(pts, distance=distance, iterations=iterations, seed=seed, voxel=voxel,
                         max_planes=max(1, max_planes), min_points=min_points)
    if not planes:
        raise NoTableError("no plane in the cloud", detail={"points": len(pts)})
    up = None if expected_up is None else np.asarray(expected_up, dtype=np.float64) / np.linalg.norm(expected_up)
    vp = np.asarray(viewpoint, dtype=np.float64)
    cands = [_judge(pts, n, d, vp, distance, min_points, min_fraction, up, max_tilt_deg, seed_point,
                    max_seed_height, expected_height, height_tolerance) for n, d in planes]
    ok = [c for c in cands if not c.reason]
    if not ok:
        first = cands[0]
        message = {
            "small": "no plane large enough to be the table",
            "tilted": "the dominant plane is not horizontal, so it is not the table",
        }.get(first.reason.split(":")[0], "no plane where the table should be")
        if len(cands) > 1:
            message = "no plane qualifies as the table (" + ", ".join(c.reason for c in cands) + ")"
        detail = {"planes": [c.summary() for c in cands], "min_fraction": min_fraction,
                  "max_tilt_deg": max_tilt_deg, "inliers": int(first.inliers.sum()),
                  "fraction": round(float(first.inliers.mean()), 3)}
        if first.tilt_deg is not None:
            detail["tilt_deg"] = round(first.tilt_deg, 1)
        raise NoTableError(message, detail=detail)
    best = max(ok, key=lambda c: int(c.inliers.sum()))
    centre = pts[best.inliers].mean(axis=0)
    return TableFit(plane=Plane(normal=best.normal, offset=best.offset, center=centre), inliers=best.inliers,
                    fraction=float(best.inliers.mean()))


def _judge(pts: np.ndarray, n: np.ndarray, d: float, viewpoint: np.ndarray, distance: float, min_points: int,
           min_fraction: float, up: np.ndarray | None, max_tilt_deg: float, seed_point: np.ndarray | None,
           max_seed_height: float | None, expected_height: float | None, height_tolerance: float
           ) -> PlaneCandidate:
    """One plane against the table prior; ``reason`` names the first test it fails."""
    if float(viewpoint @ n + d) < 0:  # face the camera: up from the table
        n, d = -n, -d
    inl = np.abs(pts @ n + d) < distance
    tilt = None if up is None else float(np.degrees(np.arccos(np.clip(n @ up, -1.0, 1.0))))
    seed_h = None if seed_point is None else float(np.asarray(seed_point, dtype=np.float64) @ n + d)
    table_h = None
    if up is not None and seed_point is not None:
        foot = np.asarray(seed_point, dtype=np.float64) - seed_h * n
        table_h = float(foot @ up)
    c = PlaneCandidate(normal=n, offset=float(d), inliers=inl, tilt_deg=tilt, seed_height=seed_h, table_height=table_h)
    if inl.sum() < min_points or inl.mean() < min_fraction:
        c.reason = f"small: {int(inl.sum())} points"
    elif tilt is not None and tilt > max_tilt_deg:
        c.reason = f"tilted: {tilt:.0f} deg"
    elif seed_h is not None and seed_h < -2.0 * distance:
        c.reason = f"above the object: seed {seed_h * 1e3:.0f} mm"
    elif seed_h is not None and max_seed_height is not None and seed_h > max_seed_height:
        c.reason = f"far below the object: seed {seed_h * 1e3:.0f} mm"
    elif table_h is not None and expected_height is not None and abs(table_h - expected_height) > height_tolerance:
        c.reason = f"height: {table_h * 1e3:.0f} mm"
    return c
