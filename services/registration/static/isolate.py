"""Object isolation: drop the table, cluster what stands on it, keep the cluster where the camera looks.

The paper's rule: DBSCAN clusters above the table, and the goal object is the cluster nearest the first
scan's image centre at its centre depth. DBSCAN runs on a coarser copy of the cloud (it is the slow part)
and labels are carried back to every point by nearest neighbour.

An object need not stand on the table itself: on a turntable or a platform it stands on a support surface
above the table plane, and the cluster there (platform top and object, held apart from the platform's base by
the shadow under its rim) floats above the table. Such a cluster is kept when its lowest horizontal face is a
support (``support_surface``): the object is what stands on that face, cut from it like from the table.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy.spatial import ConvexHull, QhullError, cKDTree

from common.messages import Plane
from services.registration.cloud import o3d_seeded

from .errors import NoObjectError


@dataclass
class Isolation:
    mask: np.ndarray  # bool over the input points: the goal object
    n_clusters: int
    cluster_sizes: list[int]  # points per cluster at the clustering voxel, selected first
    selection_distance: float  # m, from the seed to the chosen cluster
    support: Plane | None = None  # the surface the object stands on when it is not the table (a platform top)


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
    smaller than ``min_object_points`` are noise. With ``max_support_gap`` a cluster whose lowest point is more
    than that above the table does not stand on it: it is kept only as what stands on its own lowest horizontal
    face (a turntable's or platform's top, ``support_surface``), cut from that face, which is then the
    ``support`` of the chosen cluster. The chosen cluster is the one nearest the seed: by its
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
    # candidates: (coarse points of the cluster, the support plane when it is not the table)
    candidates: list[tuple[np.ndarray, Plane | None]] = [(labels == k, None) for k in keep]
    if max_support_gap is not None and keep.size:
        # an object stands on the table, or on a support surface above it (a turntable, a platform): a cluster
        # whose lowest point floats higher and has no horizontal face to stand on is something else (an arm,
        # a shelf edge, a chair seen over the table edge)
        low = table.signed_distance(cpts)
        standing = []
        for sel, _ in candidates:
            if low[sel].min() <= clearance + max_support_gap:
                standing.append((sel, None))
                continue
            standing.extend(_on_support(cpts, sel, table, clearance=clearance, max_support_gap=max_support_gap,
                                        eps=eps, min_points=min_points, min_object_points=min_object_points))
        candidates = standing
    if not candidates:
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
    for sel, _ in candidates:
        if select_by == "centroid":
            c = cpts[sel].mean(axis=0, keepdims=True)
            scores.append(float(seed_distance(c, seed_point, ray_origin, ray_dir)[0]))
        else:
            scores.append(float(dist[sel].min()))
    order = np.argsort(scores)
    best, support = candidates[int(order[0])]
    # carry the coarse labels back to every above-table point by nearest coarse point
    _, nn = cKDTree(cpts).query(pts_above, k=1)
    chosen = best[nn]
    if support is not None:  # the support's own face is not the object, like the table's
        chosen &= support.signed_distance(pts_above) > clearance
    mask = np.zeros(len(points), dtype=bool)
    mask[np.flatnonzero(above)[chosen]] = True
    sizes = [int(candidates[int(i)][0].sum()) for i in order]
    return Isolation(mask=mask, n_clusters=len(candidates), cluster_sizes=sizes,
                     selection_distance=float(scores[int(order[0])]), support=support)


def support_surface(pts: np.ndarray, table: Plane, *, min_points: int, distance: float,
                    max_tilt_deg: float = 10.0, planes: int = 3) -> Plane | None:
    """The lowest horizontal upward face among ``pts`` (a cluster floating above the table), as a plane parallel
    to the table at that face's height; None when the cluster has no such face of ``min_points`` points.

    Why the lowest: a platform's top is the bottom of what stands on it (an object's own top is higher). Why
    parallel to the table: every view of a sequence then cuts its object at the same height along the same
    axis (a face fitted per view would tilt the turn axis by its noise)."""
    if len(pts) < min_points:
        return None
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3.0 * distance, max_nn=30))
    upward = np.abs(np.asarray(pcd.normals) @ table.normal) > np.cos(np.radians(max_tilt_deg))
    faces = pcd.select_by_index(np.flatnonzero(upward))
    heights = []
    for k in range(planes):
        if len(faces.points) < min_points:
            break
        with o3d_seeded(k):  # the same cluster gives the same face in every run
            model, inliers = faces.segment_plane(distance, 3, 200)
        if len(inliers) < min_points:
            break
        tilt = np.degrees(np.arccos(min(1.0, abs(float(np.asarray(model[:3]) @ table.normal)))))
        if tilt <= max_tilt_deg:
            heights.append(float(np.median(table.signed_distance(np.asarray(faces.points)[inliers]))))
        faces = faces.select_by_index(inliers, invert=True)
    if not heights:
        return None
    h = min(heights)
    return Plane(normal=table.normal.copy(), offset=float(table.offset - h),
                 center=np.asarray(table.center, dtype=np.float64) + h * table.normal, frame=table.frame)


def _on_support(cpts: np.ndarray, sel: np.ndarray, table: Plane, *, clearance: float, max_support_gap: float,
                eps: float, min_points: int, min_object_points: int) -> list[tuple[np.ndarray, Plane]]:
    """The objects standing on a floating cluster's support surface (``support_surface``): the cluster's
    points above that face, clustered again, each of object size with its lowest point on the face; none when
    the cluster has no face to stand on."""
    support = support_surface(cpts[sel], table, min_points=min_object_points, distance=clearance)
    if support is None:
        return []
    idx = np.flatnonzero(sel)
    h = support.signed_distance(cpts[idx])
    up = idx[h > clearance]
    if len(up) < min_object_points:
        return []
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cpts[up]))
    sub = np.asarray(pcd.cluster_dbscan(eps=eps, min_points=min_points, print_progress=False))
    out = []
    for k in np.unique(sub[sub >= 0]):
        members = up[sub == k]
        if len(members) >= min_object_points and support.signed_distance(cpts[members]).min() <= (
                clearance + max_support_gap):
            mask = np.zeros(len(cpts), dtype=bool)
            mask[members] = True
            out.append((mask, support))
    return out


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
