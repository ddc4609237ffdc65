"""The rectangle of a view's images the RGB-D odometry runs on: the region of interest's pixels, not the whole frame.

Why: after the crop to the region of interest the object, and the table around it that pins the camera's slide,
fill a rectangle of ~55-65 % of a 640 x 480 scan; the rest (far table, floor, room) is cut from the clouds already,
yet Open3D's odometry still builds pyramids and gradients of, and matches, every pixel of both images, at a fixed
cost of ~0.24 CPU-s a full-resolution call. One rectangle serves the whole view (the odometry takes one intrinsic
for both images): the union of every scan's ROI pixel bounding box, grown by a margin (image context for the
gradients at its border, and room for the other scan's pixels to land in), its corners snapped outward to a
multiple of the coarsest pyramid level's pixel so every level holds exactly the pixels of the uncropped pyramid.
Every pixel inside keeps its data: depth outside the ROI but inside the rectangle still takes part.

Off by default (``StaticConfig.odometry_window_margin`` None): over ``bench reconstruct``'s sessions it cut the
odometry's CPU by 14-33 %, but the table outside the rectangle is part of what pins the camera's
slide, and without it symmetric shapes slid by centimetres (docs/static-registration.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .config import StaticConfig


@dataclass(frozen=True)
class ImageWindow:
    """Columns ``x0 .. x1 - 1`` and rows ``y0 .. y1 - 1`` of the full-resolution image."""

    x0: int
    y0: int
    x1: int
    y1: int

    @property
    def width(self) -> int:
        return self.x1 - self.x0

    @property
    def height(self) -> int:
        return self.y1 - self.y0


def cut_to(image: np.ndarray, window: ImageWindow | None) -> np.ndarray:
    """``image`` (rows x columns [x channels]) cut to ``window``; None: the whole image."""
    return image if window is None else image[window.y0 : window.y1, window.x0 : window.x1]


def pyramid_alignment(cfg: StaticConfig) -> int:
    """Full-resolution pixels per pixel of the coarsest pyramid level of either odometry pass (forward and reverse
    seed): a window corner on a multiple of it keeps every level's pixels those of the uncropped image."""
    forward = cfg.odometry_step * 2 ** (len(cfg.odometry_iterations) - 1)
    if cfg.odometry_seed_iterations is None:
        return forward
    seed = cfg.odometry_step * cfg.odometry_seed_step * 2 ** (len(cfg.odometry_seed_iterations) - 1)
    return math.lcm(forward, seed)


def roi_window(pixels: Sequence[np.ndarray], width: int, height: int, margin: int, align: int) -> ImageWindow:
    """The union of the bounding boxes of each scan's flat pixel indices, grown by ``margin`` px, corners snapped
    outward to multiples of ``align`` and clipped to the ``width`` x ``height`` image."""
    if align < 1 or margin < 0:
        raise ValueError(f"align must be at least 1 and margin non-negative, got {align}, {margin}")
    flat = np.concatenate([np.asarray(p, dtype=np.int64).ravel() for p in pixels]) if pixels else np.empty(0, int)
    if flat.size == 0:
        return ImageWindow(0, 0, width, height)
    rows, cols = np.divmod(flat, width)
    x0 = max(0, (int(cols.min()) - margin) // align * align)
    y0 = max(0, (int(rows.min()) - margin) // align * align)
    x1 = min(width, -(-(int(cols.max()) + 1 + margin) // align) * align)
    y1 = min(height, -(-(int(rows.max()) + 1 + margin) // align) * align)
    return ImageWindow(x0, y0, x1, y1)


def odometry_window(pixels: Sequence[np.ndarray], width: int, height: int, has_roi: bool,
                    cfg: StaticConfig) -> ImageWindow | None:
    """The view's odometry window, or None (the whole image) when the scans were not cropped to a region of
    interest (no seed point, ``roi_radius`` None) or the crop is off (``odometry_window_margin`` None)."""
    if not has_roi or cfg.odometry_window_margin is None:
        return None
    window = roi_window(pixels, width, height, cfg.odometry_window_margin, pyramid_alignment(cfg))
    return None if (window.width, window.height) == (width, height) else window
