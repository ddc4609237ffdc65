"""Object isolation: drop the table, cluster what stands on it, keep the cluster where the camera looks.

The paper's rule: DBSCAN clusters above the table, and the goal object is the cluster nearest the first
scan's image centre at its centre depth. DBSCAN runs on a coarser copy of the cloud (it is the slow part)
and labels are carried back to every point by nearest neighbour.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy.spatial import ConvexHull, QhullError, cKDTree

from common.messages import Plane

from .errors import NoObjectError


@dataclass
class Isolation:
    mask: np.ndarray  # bool over the input points: the goal object
    n_clusters: int
    cluster_sizes: list[int]  # points per cluster at the clustering voxel, selected first
    selection_distance: float  # m, from the seed to the chosen cluster


def seed_distance(
    points: np.ndarray, seed_point: np.ndarray | None, ray_origin: np.ndarray, ray_dir: np.ndarray
) -> np.ndarray:
    """Distance of each point to the seed point, or to the centre ray when the centre depth is unknown."""
    if seed_point is not None:
        return np.linalg.norm(points - seed_point, axis=1)
    rel = points - ray_origin
    along = rel @ ray_dir
    return np.linalg.norm(rel - np.outer(along, ray_dir), axis=1)


def isolate_object(
    points: np.ndarray,
    table: Plane,
    *,
    seed_point: np.ndarray | None,
    ray_origin: np.ndarray,
    ray_dir: np.ndarray,
    clearance: float,
    max_height: float,
    cluster_voxel: float,
    eps: float,
    min_points: int,
    min_object_points: int,
    select_by: str = "nearest_point",
    max_support_gap: float | None = None,
) -> Isolation:
    """Pick the goal object's points among ``points`` (already in the table's frame, e.g. ``base``).

    Points between ``clearance`` and ``max_height`` above the table are clustered with DBSCAN; clusters
    smaller than ``min_object_points`` are noise, and with ``max_support_gap`` so are clusters whose lowest
    point is more than that above the table (not standing on it). The chosen cluster is the one nearest the seed: by its
    nearest point (``nearest_point``, robust when the seed is on the object's face) or by its centroid
    (``centroid``, the paper's rule). Raises ``NoObjectError`` when no cluster qualifies.
    """
    height = table.signed_distance(points)
    above = (height > clearance) & (height < max_height)
    if above.sum() < min_object_points:
        raise NoObjectError("nothing stands on the table", detail={"points_above_table": int(above.sum())})
    pts_above = points[above]
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts_above))
    coarse = pcd.voxel_down_sample(cluster_voxel) if cluster_voxel > 0 else pcd
    cpts = np.asarray(coarse.points)
    labels = np.asarray(coarse.cluster_dbscan(eps=eps, min_points=min_points, print_progress=False))
    ids, counts = np.unique(labels[labels >= 0], return_counts=True)
    keep = ids[counts >= min_object_points]
    if max_support_gap is not None and keep.size:
        # an object stands on the table: a cluster whose lowest point floats higher is something else
        # (an arm, a shelf, a chair seen over the table edge)
        low = table.signed_distance(cpts)
        keep = np.array([k for k in keep if low[labels == k].min() <= clearance + max_support_gap], dtype=keep.dtype)
    if keep.size == 0:
        raise NoObjectError(
            "no cluster of object size above the table",
            detail={
                "clusters": int(ids.size),
                "largest": int(counts.max()) if counts.size else 0,
                "min_object_points": min_object_points,
            },
        )
    dist = seed_distance(cpts, seed_point, ray_origin, ray_dir)
    scores = []
    for k in keep:
        sel = labels == k
        if select_by == "centroid":
            c = cpts[sel].mean(axis=0, keepdims=True)
            scores.append(float(seed_distance(c, seed_point, ray_origin, ray_dir)[0]))
        else:
            scores.append(float(dist[sel].min()))
    order = np.argsort(scores)
    best = keep[order[0]]
    # carry the coarse labels back to every above-table point by nearest coarse point
    _, nn = cKDTree(cpts).query(pts_above, k=1)
    mask = np.zeros(len(points), dtype=bool)
    mask[np.flatnonzero(above)[labels[nn] == best]] = True
    sizes = [int(counts[ids == keep[i]][0]) for i in order]
    return Isolation(
        mask=mask, n_clusters=int(keep.size), cluster_sizes=sizes, selection_distance=float(scores[order[0]])
    )


def footprint_centre(points: np.ndarray, table: Plane) -> tuple[np.ndarray, float]:
    """Object centre on the table and its height.

    The centre is the middle of the minimum-area rectangle around the points projected on the table (found
    by rotating calipers over the 2-D convex hull), lifted to the table. A partial view biases any
    estimate toward the camera; a rectangle is stable under that and exact for boxes seen on two sides.
    Height is the 99.5th percentile of height above the table (robust to a stray point).
    """
    n = table.normal
    h = points @ n + table.offset
    height = float(np.percentile(h, 99.5)) if len(h) else 0.0
    a = np.cross(n, [1.0, 0.0, 0.0])
    if np.linalg.norm(a) < 1e-6:
        a = np.cross(n, [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    foot = points - np.outer(h, n)  # projected onto the plane
    uv = np.column_stack([foot @ a, foot @ b])
    try:
        hull = uv[ConvexHull(uv).vertices]
    except (QhullError, ValueError):  # degenerate (collinear or too few points) footprint
        hull = uv
    best = None
    for i in range(len(hull)):
        e = hull[(i + 1) % len(hull)] - hull[i]
        if np.linalg.norm(e) < 1e-9:
            continue
        e = e / np.linalg.norm(e)
        f = np.array([-e[1], e[0]])
        pe, pf = hull @ e, hull @ f
        area = (pe.max() - pe.min()) * (pf.max() - pf.min())
        if best is None or area < best[0]:
            mid = e * (pe.max() + pe.min()) / 2 + f * (pf.max() + pf.min()) / 2
            best = (area, mid)
    mid = uv.mean(axis=0) if best is None else best[1]
    centre = mid[0] * a + mid[1] * b - table.offset * n  # on the plane
    return centre, height
