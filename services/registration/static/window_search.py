"""The default profile's fallback search, confined to what the arm's accuracy allows around its prior.

When the local paths fail, the pose is still within the plausible window (``plausibility.py``) or it is no
pose the arm could have been at. So instead of a global, prior-free match (FPFH RANSAC: seconds per pair,
randomised, and free to find a symmetric object's turned twin 90 degrees away), ICP runs on the table-free
clouds from a fixed grid of starts inside the window:

- yaw about the table normal through the object's centroid at ``search_yaw_fractions`` of the rotation
  bound, and tilt about the two horizontal axes at +-``search_tilt_fraction`` of it;
- each with the prior's shift and with the shift that lines up the two objects' centroids (clipped to the
  translation bound).

A result that leaves the window is discarded before it is scored; the rest are ranked by the fitness of the
table-free clouds. No random draw and a stable order: the same scans give the same candidates, run after run.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

from common.geometry import make_transform, rotation_about_axis

from . import pairwise as pw
from .config import StaticConfig
from .plausibility import correction_bound, plausible


def _about(point: np.ndarray, axis: np.ndarray, deg: float) -> np.ndarray:
    """Rotation by ``deg`` about ``axis`` through ``point`` (4x4)."""
    R = rotation_about_axis(axis, np.radians(deg))
    return make_transform(R, point - R @ point)


def _axes(up: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(up, horizontal 1, horizontal 2), orthonormal; without a known up, the camera's -y (image up)."""
    u = np.array([0.0, -1.0, 0.0]) if up is None else np.asarray(up, dtype=np.float64)
    u = u / np.linalg.norm(u)
    helper = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    h1 = np.cross(u, helper)
    h1 /= np.linalg.norm(h1)
    return u, h1, np.cross(u, h1)


def starts(src: o3d.geometry.PointCloud, tgt: o3d.geometry.PointCloud, prior: np.ndarray, cfg: StaticConfig,
           up: np.ndarray | None) -> list[np.ndarray]:
    """The grid of starting poses (source camera -> target camera), all inside the plausible window."""
    bound = correction_bound(prior, cfg)
    centre = np.asarray(tgt.points).mean(axis=0)
    src_centre = np.asarray(src.points).mean(axis=0)
    u, h1, h2 = _axes(up)
    turns = [(u, f * bound.deg) for f in cfg.search_yaw_fractions]
    turns += [(h, s * cfg.search_tilt_fraction * bound.deg) for h in (h1, h2) for s in (-1.0, 1.0)]
    out: list[np.ndarray] = []
    for axis, deg in turns:
        T = _about(centre, axis, deg) @ prior
        out.append(T)
        shift = centre - (T[:3, :3] @ src_centre + T[:3, 3])
        norm = float(np.linalg.norm(shift))
        if norm > 0.002:  # the centroids already agree to 2 mm: that start is the one above
            shifted = T.copy()
            shifted[:3, 3] += shift * min(1.0, 0.8 * bound.m / norm)
            out.append(shifted)
    return [T for T in out if plausible(T, prior, cfg)]


def window_search(src: o3d.geometry.PointCloud, tgt: o3d.geometry.PointCloud, src_check: o3d.geometry.PointCloud,
                  tgt_check: o3d.geometry.PointCloud, prior: np.ndarray, cfg: StaticConfig,
                  up: np.ndarray | None) -> list[np.ndarray]:
    """ICP from every start on the table-free clouds (``src``/``tgt`` with normals); the results inside the
    window, best first (fitness on the table-free check clouds, then RMSE, then grid order)."""
    corr = cfg.check_voxel * cfg.check_corr_factor
    found: list[tuple[float, float, int, np.ndarray]] = []
    for k, T in enumerate(starts(src, tgt, prior, cfg, up)):
        for c in cfg.search_corr:
            T = pw.icp_point_to_plane(src, tgt, c, T, cfg.search_iterations).T
        if not plausible(T, prior, cfg):
            continue  # left the window: whatever it fits, the arm was not there
        res = pw.evaluate(src_check, tgt_check, T, corr)
        found.append((-round(res.fitness, 3), res.rmse, k, T))
    found.sort(key=lambda f: (f[0], f[1], f[2]))
    return [f[3] for f in found]
