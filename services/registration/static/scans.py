"""The scans of one view as both profiles take them: loaded, checked, seeded, cropped, table stripped.

Shared by ``default_profile`` and ``paper_profile`` so that the two differ only in how they align the scans.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from common.messages import RGBDFrame
from services.registration.cloud import CloudError, FramePoints, frame_points, o3d_seeded

from .config import StaticConfig
from .errors import BadFramesError, EmptyDepthError

MIN_SCAN_POINTS = 500  # a scan with fewer valid depth points than this is treated as empty


@dataclass
class Scan:
    """One frame's points in its camera frame (cropped to the ROI later), with its believed pose."""

    index: int
    pts_cam: FramePoints
    T_believed: np.ndarray


def load_scans(frames: list[RGBDFrame], cfg: StaticConfig) -> list[Scan]:
    """Back-project every frame in its own camera frame; unusable input raises a typed error."""
    if not isinstance(frames, list | tuple) or len(frames) == 0:
        raise BadFramesError("register_view needs at least one RGBDFrame")
    scans = []
    for i, f in enumerate(frames):
        if not isinstance(f, RGBDFrame):
            raise BadFramesError(f"frame {i} is a {type(f).__name__}, not an RGBDFrame")
        try:
            pts = frame_points(f, depth_min=cfg.depth_min, depth_max=cfg.depth_max, edge_threshold=cfg.edge_threshold)
        except CloudError as exc:
            raise BadFramesError(f"frame {i}: {exc.message}", detail={"frame": i, **exc.detail}) from None
        if len(pts) < MIN_SCAN_POINTS:
            raise EmptyDepthError(
                f"frame {i} has no usable depth",
                detail={
                    "frame": i,
                    "valid_points": len(pts),
                    "depth_range_m": [cfg.depth_min, cfg.depth_max],
                },
            )
        scans.append(Scan(index=i, pts_cam=pts, T_believed=np.asarray(f.T_base_camera, dtype=np.float64)))
    sizes = {np.asarray(f.depth).shape for f in frames}
    if len(sizes) > 1:
        raise BadFramesError(
            "the scans of one view must come from one camera (image sizes differ)",
            detail={"sizes": sorted(list(s) for s in sizes)},
        )
    return scans


def centre_depth(frame: RGBDFrame, cfg: StaticConfig) -> float | None:
    """Median valid depth (m) in a window at the principal point: the paper's "centre depth"."""
    h, w = frame.depth.shape
    u, v = int(round(frame.intrinsics.cx)), int(round(frame.intrinsics.cy))
    for half in (cfg.centre_window // 2, cfg.centre_window * 2):
        win = frame.depth[max(0, v - half) : min(h, v + half + 1), max(0, u - half) : min(w, u + half + 1)]
        z = win.astype(np.float64).ravel() * frame.depth_scale
        z = z[(z >= cfg.depth_min) & (z <= cfg.depth_max)]
        if z.size:
            return float(np.median(z))
    return None


def roi_mask(xyz_base: np.ndarray, seed: np.ndarray, cfg: StaticConfig) -> np.ndarray:
    """Points in the region of interest around the seed point.

    With a known up axis (``base``: table top at height 0 along it), a cylinder about that axis through the
    seed, from ``roi_below`` under the table to ``roi_above`` over it; without one, a sphere about the seed.
    """
    rel = xyz_base - seed
    if cfg.expected_up is None:
        return np.einsum("ij,ij->i", rel, rel) <= cfg.roi_radius**2
    up = np.asarray(cfg.expected_up, dtype=np.float64)
    up = up / np.linalg.norm(up)
    height = xyz_base @ up
    radial = rel - np.outer(rel @ up, up)
    return (
        (np.einsum("ij,ij->i", radial, radial) <= cfg.roi_radius**2)
        & (height >= -cfg.roi_below)
        & (height <= cfg.roi_above)
    )


def strip_table(pcd: o3d.geometry.PointCloud, cfg: StaticConfig, seed: int) -> o3d.geometry.PointCloud:
    """Remove the largest RANSAC plane (the table) from a scan, as the paper does before re-registering."""
    coarse = pcd.voxel_down_sample(cfg.plane_voxel)
    if len(coarse.points) < 3:
        return pcd
    with o3d_seeded(seed):
        model, _ = coarse.segment_plane(cfg.plane_distance, 3, cfg.plane_iterations)
    n = np.asarray(model[:3])
    dist = np.abs(np.asarray(pcd.points) @ n + model[3]) / np.linalg.norm(n)
    kept = pcd.select_by_index(np.flatnonzero(dist > cfg.plane_distance))
    return kept if len(kept.points) >= MIN_SCAN_POINTS else pcd
