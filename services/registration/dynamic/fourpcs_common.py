"""Shared pieces of the global-registration building blocks: the result type and input checks.

Kept apart from ``fourpcs.py`` so that ``global_registration.py`` (which wraps 4PCS, FPFH-RANSAC and FGR)
and ``evaluation.py`` can use the same result type and the same typed input errors without import cycles.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from common.errors import InvalidRequest


class PointCloudInputError(InvalidRequest):
    """A cloud handed to registration/evaluation is unusable (wrong shape, NaN/inf, too few points)."""

    code = "invalid_point_cloud"


@dataclass(frozen=True)
class GlobalResult:
    """Outcome of one global registration: ``T`` maps source points onto the target (``p_t = T @ p_s``).

    ``lcp_score`` is the Largest Common Pointset score: the fraction of (sampled, down-sampled) source points
    that land within ``delta`` of a target point after ``T``. ``score`` is the weighted LCP,
    mean(max(0, 1 - d^2 / delta^2)): it does not saturate at 1 the way LCP does on small objects, so it is
    what candidates (and overlaps, and methods) are ranked by. Both are comparable across methods as long as
    the same ``delta`` and clouds are used, which is why ``global_register`` computes them for every method.
    """

    T: np.ndarray
    lcp_score: float
    n_bases_tried: int
    seconds: float
    score: float = 0.0
    method: str = "4pcs"
    overlap: float | None = None
    extra: dict = field(default_factory=dict)


def as_xyz(points: object, name: str = "points", *, min_points: int = 1) -> np.ndarray:
    """Return ``points`` as a finite float64 (N, 3) array, or raise a typed error saying what is wrong.

    Accepts numpy arrays, anything array-like, and Open3D point clouds (their ``.points``).
    """
    if hasattr(points, "points") and not isinstance(points, np.ndarray):  # open3d.geometry.PointCloud
        points = np.asarray(points.points)
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise PointCloudInputError(f"{name} is not numeric", detail={"field": name}) from exc
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise PointCloudInputError(f"{name} must have shape (N, 3), got {arr.shape}",
                                   code="bad_shape", detail={"field": name, "shape": list(arr.shape)})
    if arr.shape[0] < min_points:
        raise PointCloudInputError(f"{name} has {arr.shape[0]} points, need at least {min_points}",
                                   code="too_few_points", detail={"field": name, "n": int(arr.shape[0])})
    if not np.all(np.isfinite(arr)):
        raise PointCloudInputError(f"{name} contains NaN or inf", code="non_finite", detail={"field": name})
    return arr


def as_optional_rows(values: object, n: int, name: str) -> np.ndarray | None:
    """Validate an optional per-point (n, 3) array (normals, colors) against the point count."""
    if values is None:
        return None
    arr = as_xyz(values, name)
    if arr.shape[0] != n:
        raise PointCloudInputError(f"{name} has {arr.shape[0]} rows, the cloud has {n}",
                                   code="bad_shape", detail={"field": name})
    return arr


def check_transform(T: object, name: str = "T") -> np.ndarray:
    """A finite 4x4 float64 matrix, or a typed error."""
    arr = np.asarray(T, dtype=np.float64)
    if arr.shape != (4, 4) or not np.all(np.isfinite(arr)):
        raise PointCloudInputError(f"{name} must be a finite 4x4 matrix, got shape {arr.shape}",
                                   code="bad_transform", detail={"field": name})
    return arr
