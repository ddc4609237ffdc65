"""GOOD descriptors for the library: one of the whole model, and one per synthetic partial view of it.

The issue asks for the GOOD descriptor of the whole model (kept in the metadata). A query, though, is a
*partial* view: the front of an object seen from a few camera poses. GOOD of a half-seen object differs from
GOOD of the whole one (its PCA frame and projections change), so comparing a view against whole-model
descriptors ranks poorly. What works is what view-based recognition does: render the stored model from
many directions (Open3D's hidden point removal keeps the points a camera there would see), describe each
such synthetic view, and score a query by its closest synthetic view. Directions are spread evenly over
the sphere (a Fibonacci lattice), so nothing assumes which way is up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from services.library.errors import BadModelInput
from services.registration.api import PointCloudInputError, good_descriptor, good_distance


@dataclass(frozen=True)
class DescriptorConfig:
    """How models and queries are described.

    ``n_bins``: GOOD resolutions used together (distance = mean over them; coarse bins tolerate the
    noise of partial views, finer ones separate similar shapes). ``views``: synthetic viewpoints per
    model. ``max_points``: clouds are randomly thinned to this before describing (GOOD is a histogram,
    it does not need every point, and hidden point removal is O(n log n)).
    """

    n_bins: tuple[int, ...] = (5, 10)
    views: int = 16
    max_points: int = 8000
    metric: str = "chi2"
    seed: int = 0


def check_xyz(points: np.ndarray, what: str = "cloud", min_points: int = 10) -> np.ndarray:
    """(N, 3) finite float64 array or ``BadModelInput``: a bad cloud is a typed error, never a crash."""
    arr = np.asarray(points)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise BadModelInput(f"{what} must be an (N, 3) array", detail={"shape": list(arr.shape)})
    if not np.issubdtype(arr.dtype, np.number):
        raise BadModelInput(f"{what} must be numeric", detail={"dtype": str(arr.dtype)})
    arr = arr.astype(np.float64, copy=False)
    if not np.isfinite(arr).all():
        raise BadModelInput(f"{what} contains NaN or inf", detail={"bad_rows": int((~np.isfinite(arr)).any(1).sum())})
    if arr.shape[0] < min_points:
        raise BadModelInput(f"{what} has {arr.shape[0]} points, at least {min_points} needed",
                            code="empty_cloud", detail={"points": int(arr.shape[0])})
    return arr


def thin(points: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    """At most ``n`` rows, chosen at random reproducibly."""
    if points.shape[0] <= n:
        return points
    idx = np.random.default_rng(seed).choice(points.shape[0], n, replace=False)
    return points[np.sort(idx)]


def describe(points: np.ndarray, config: DescriptorConfig = DescriptorConfig()) -> np.ndarray:
    """GOOD at every ``n_bins`` resolution, concatenated (length sum 3 n^2)."""
    xyz = thin(check_xyz(points), config.max_points, config.seed)
    try:
        return np.concatenate([good_descriptor(xyz, n) for n in config.n_bins])
    except PointCloudInputError as exc:
        raise BadModelInput(f"cannot describe cloud: {exc.message}", detail=exc.detail) from None


def distance(a: np.ndarray, b: np.ndarray, config: DescriptorConfig = DescriptorConfig()) -> float:
    """Mean GOOD distance over the resolutions (each term in [0, 3] for chi2, so none dominates)."""
    out, start = [], 0
    for n in config.n_bins:
        size = 3 * n * n
        out.append(good_distance(a[start:start + size], b[start:start + size], config.metric))
        start += size
    if start != np.asarray(a).size or start != np.asarray(b).size:
        raise BadModelInput("descriptor lengths do not match the configured resolutions",
                            detail={"expected": start, "a": int(np.asarray(a).size), "b": int(np.asarray(b).size)})
    return float(np.mean(out))


def sphere_directions(count: int) -> np.ndarray:
    """``count`` unit vectors spread evenly over the sphere (Fibonacci lattice)."""
    i = np.arange(count) + 0.5
    z = 1.0 - 2.0 * i / count
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    phi = np.pi * (1.0 + 5.0**0.5) * i
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def synthetic_views(points: np.ndarray, count: int, *, min_points: int = 50) -> list[np.ndarray]:
    """The parts of a cloud visible from ``count`` directions around it (hidden point removal).

    The camera sits 3 diameters away; HPR's radius is 100x that distance, the value Katz et al. suggest
    for dense clouds. Views with fewer than ``min_points`` visible points are skipped.
    """
    xyz = check_xyz(points)
    centre = xyz.mean(axis=0)
    diameter = float(np.linalg.norm(xyz.max(axis=0) - xyz.min(axis=0))) or 1e-3
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
    out = []
    for d in sphere_directions(count):
        cam = centre + 3.0 * diameter * d
        _, idx = pcd.hidden_point_removal(cam, 300.0 * diameter)
        if len(idx) >= min_points:
            out.append(xyz[np.asarray(idx)])
    return out


def model_descriptors(points: np.ndarray, config: DescriptorConfig = DescriptorConfig()) -> dict:
    """What the library stores for a model: ``whole`` (GOOD of the whole model) and ``views`` (V, D)."""
    xyz = thin(check_xyz(points), config.max_points, config.seed)
    whole = describe(xyz, config)
    views = [describe(v, config) for v in synthetic_views(xyz, config.views)]
    return {"n_bins": list(config.n_bins), "whole": whole,
            "views": np.vstack(views) if views else whole[None, :]}


def view_distance(query: np.ndarray, views: np.ndarray, config: DescriptorConfig = DescriptorConfig()) -> float:
    """Distance of a query's descriptor to a model: that of its closest synthetic view."""
    return min(distance(query, v, config) for v in np.atleast_2d(views))
