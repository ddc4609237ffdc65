"""Figures of a depth frame that say how harsh its sensor is: one measure for real and twin frames alike.

The twin's D435 model (``sensor_model.py``) is calibrated by measuring real RealSense frames and twin frames
with *these same functions* and matching the figures (``bench/sensor.py``). No ground truth is needed, so
any real tabletop frame works:

* ``plane_sigma_1m_mm`` - the table's depth residual about its best plane, as a robust standard deviation
  (1.4826 x MAD), each residual divided by z^2 so frames at different distances compare (stereo noise grows
  with z^2): the residual a table at 1 m would show. It includes what a plane fit sees of structured error.
* ``edge_dropout_per_edge`` - invalid pixels next to depth discontinuities (the stereo occlusion shadow
  beside foreground objects, the matcher giving up at edges), per edge pixel: about the invalid band's width.
* ``flying_per_edge`` - valid pixels near an edge whose depth sits between their nearest and farthest
  8-neighbour (> ``FLY_MARGIN`` x z from both), per edge pixel.
* ``interior_hole_fraction`` - invalid pixels away from edges (specular spots, low texture), as a fraction
  of the frame's pixels that have data or lie in such holes (not the invalid band at the left image border,
  nor anything touching the image border: out of range or outside the right imager's view).

Edges are found on a row-filled copy of the depth (each invalid run bridged with its farther end, as the
occluded background behind a shadow is): 4-neighbours whose depths differ by more than ``JUMP_REL`` x z.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import cv2
import numpy as np
from numba import njit

from services.sim.errors import SimInputError

JUMP_REL = 0.03  # a depth discontinuity: neighbours more than 3 % of the depth apart
FLY_MARGIN = 0.015  # a flying pixel: > 1.5 % of its depth from both its nearest and farthest 8-neighbour
EDGE_RADIUS = 2  # pixels within this distance of a discontinuity are "at the edge"
PLANE_BAND = 0.02  # residuals (normalised to 1 m) within 20 mm count as on the plane


@dataclass(frozen=True)
class DepthFigures:
    """The measured figures of one frame (see the module docstring)."""

    plane_sigma_1m_mm: float
    edge_dropout_per_edge: float
    flying_per_edge: float
    interior_hole_fraction: float
    table_depth_m: float
    edge_pixels: int

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


FIGURES = ("plane_sigma_1m_mm", "edge_dropout_per_edge", "flying_per_edge", "interior_hole_fraction")


def backproject(depth_m: np.ndarray, fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """(H, W, 3) camera-frame points of a depth image (zeros where there is no depth)."""
    h, w = depth_m.shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    z = depth_m.astype(np.float64)
    return np.dstack([(u - cx) / fx * z, (v - cy) / fy * z, z])


def table_plane_sigma(depth_m: np.ndarray, fx: float, fy: float, cx: float, cy: float,
                      seed: int = 0) -> tuple[float, float]:
    """(robust residual sigma normalised to 1 m in mm, median table depth in m) of the frame's dominant plane.

    RANSAC on a subsample (threshold 1 % of depth), then a least-squares refit on the inliers; residuals
    are measured along the ray as depth differences (what stereo noise perturbs) and divided by z^2.
    """
    pts = backproject(depth_m, fx, fy, cx, cy).reshape(-1, 3)
    valid = pts[:, 2] > 0
    if valid.sum() < 1000:
        raise SimInputError("too few valid depth pixels to find a table plane", code="bad_value")
    p = pts[valid]
    rng = np.random.default_rng(seed)
    sub = p[rng.choice(len(p), size=min(len(p), 20000), replace=False)]
    best, best_n = None, -1
    for _ in range(300):
        a, b, c = sub[rng.choice(len(sub), 3, replace=False)]
        n = np.cross(b - a, c - a)
        norm = np.linalg.norm(n)
        if norm < 1e-9:
            continue
        n /= norm
        d = -n @ a
        count = int((np.abs(sub @ n + d) < 0.01 * sub[:, 2]).sum())
        if count > best_n:
            best, best_n = (n, d), count
    n, d = best
    for _ in range(3):  # least-squares refit on the points near the plane
        near = p[np.abs(p @ n + d) < 0.01 * p[:, 2]]
        c0 = near.mean(axis=0)
        n = np.linalg.svd(near - c0, full_matrices=False)[2][2]
        d = -n @ c0
    # depth along the ray where it meets the plane: z_plane = -d / (n . ray), ray = (x/z, y/z, 1)
    rays = p / p[:, 2:3]
    z_plane = -d / (rays @ n)
    r = (p[:, 2] - z_plane) / np.square(p[:, 2])  # residual normalised to 1 m
    on = np.abs(r) < PLANE_BAND
    r = r[on]
    sigma = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    return sigma * 1e3, float(np.median(p[on, 2]))


def row_filled(depth_m: np.ndarray) -> np.ndarray:
    """Each invalid run inside a row bridged with the farther of its two ends (runs at the border stay 0)."""
    out = np.ascontiguousarray(depth_m, dtype=np.float32).copy()
    _row_fill(out)
    return out


@njit(cache=True, nogil=True)
def _row_fill(depth):  # pragma: no cover - compiled
    h, w = depth.shape
    for r in range(h):
        last = -1
        for c in range(w):
            if depth[r, c] > 0:
                if last >= 0 and c - last > 1:
                    fill = max(depth[r, last], depth[r, c])
                    for k in range(last + 1, c):
                        depth[r, k] = fill
                last = c


def discontinuities(filled: np.ndarray) -> np.ndarray:
    """Pixels with a 4-neighbour more than ``JUMP_REL`` of the depth nearer or farther (both sides marked)."""
    edge = np.zeros(filled.shape, dtype=bool)
    for axis in (0, 1):
        a = filled
        b = np.roll(filled, -1, axis=axis)
        jump = (a > 0) & (b > 0) & (np.abs(a - b) > JUMP_REL * np.minimum(a, b))
        if axis == 0:
            jump[-1, :] = False
        else:
            jump[:, -1] = False
        edge |= jump
        edge |= np.roll(jump, 1, axis=axis)
    return edge


def edge_figures(depth_m: np.ndarray) -> tuple[float, float, float, int]:
    """(edge dropouts per edge pixel, flying pixels per edge pixel, interior hole fraction, edge pixels)."""
    depth = depth_m.astype(np.float32)
    filled = row_filled(depth)
    edge = discontinuities(filled)
    n_edge = int(edge.sum())
    k = 2 * EDGE_RADIUS + 1
    zone = cv2.dilate(edge.astype(np.uint8), np.ones((k, k), np.uint8)).astype(bool)
    invalid = depth <= 0
    # invalid components: an edge hole touches the edge zone; a border one is out of range / out of view
    n_lab, labels = cv2.connectedComponents(invalid.astype(np.uint8), connectivity=4)
    touches_zone = np.zeros(n_lab, dtype=bool)
    touches_zone[np.unique(labels[zone & invalid])] = True
    border = np.zeros(n_lab, dtype=bool)
    border[np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))] = True
    comp = labels[invalid]
    edge_holes = touches_zone[comp] & ~border[comp]
    interior = ~touches_zone[comp] & ~border[comp]
    # flying: valid pixels in the edge zone between their nearest and farthest 8-neighbours (a 3x3
    # window: wider ones take slanted surfaces near an edge for flying pixels)
    big = np.float32(1e9)
    near = cv2.erode(np.where(depth > 0, depth, big), np.ones((3, 3), np.uint8))
    far = cv2.dilate(depth, np.ones((3, 3), np.uint8))
    margin = FLY_MARGIN * depth
    fly = zone & (depth > 0) & (depth - near > margin) & (far - depth > margin)
    counted = int((depth > 0).sum()) + int(interior.sum())
    per = max(n_edge, 1)
    return (float(edge_holes.sum()) / per, float(fly.sum()) / per,
            float(interior.sum()) / max(counted, 1), n_edge)


def measure_depth(depth_m: np.ndarray, fx: float, fy: float, cx: float, cy: float, seed: int = 0) -> DepthFigures:
    """All figures of one depth frame (metres, 0 = no data)."""
    if depth_m.ndim != 2:
        raise SimInputError("depth must be a 2-D image", code="bad_shape")
    sigma, z_table = table_plane_sigma(depth_m, fx, fy, cx, cy, seed)
    drop, fly, holes, n_edge = edge_figures(depth_m)
    return DepthFigures(plane_sigma_1m_mm=sigma, edge_dropout_per_edge=drop, flying_per_edge=fly,
                        interior_hole_fraction=holes, table_depth_m=z_table, edge_pixels=n_edge)


def summarise(figures: list[DepthFigures]) -> dict[str, float]:
    """Median of each figure over frames (frames differ in scene; the median is robust to the odd one)."""
    if not figures:
        raise SimInputError("no frames measured", code="bad_value")
    return {name: float(np.median([getattr(f, name) for f in figures])) for name in FIGURES}
