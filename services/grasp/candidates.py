"""Candidate contact regions (GeoGrasp step 1, with the paper's bounding-box main axis).

The object is put in its table-aligned bounding box frame with the longest side as x. A slice of
``slice_thickness`` through the box middle, perpendicular to x, gives four extreme points (min/max along
y and z); around each, a box one fingertip wide along x and min(fingertip, a third of the object's
width) along y and z crops a candidate region out of the full cloud. Regions are thinned to one point
per voxel so the all-pairs ranking stays small, and each kept point gets its surface-variation
curvature from the unthinned cloud around it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.grasp.boxes import OrientedBox, table_aligned_box


@dataclass(frozen=True)
class ObjectFrame:
    """The object's table-aligned box with columns reordered so x is the longest side.

    ``local`` holds the cloud in this frame, centred on the box centre (so x = 0 is the central plane).
    """

    box: OrientedBox
    local: np.ndarray

    @property
    def rotation(self) -> np.ndarray:
        return self.box.rotation

    @property
    def center(self) -> np.ndarray:
        return self.box.center

    @property
    def extents(self) -> np.ndarray:
        return 2.0 * self.box.half_extents

    @property
    def main_axis(self) -> np.ndarray:
        return self.box.rotation[:, 0]

    def to_base(self, local_points: np.ndarray) -> np.ndarray:
        return np.asarray(local_points, float) @ self.box.rotation.T + self.box.center


def object_frame(points: np.ndarray, up: np.ndarray) -> ObjectFrame:
    """Table-aligned box of ``points`` ordered longest side first (x), then y, then z (right-handed)."""
    box = table_aligned_box(points, up)
    order = np.argsort(-box.half_extents, kind="stable")
    rotation = box.rotation[:, order].copy()
    if np.linalg.det(rotation) < 0:
        rotation[:, 2] *= -1
    aligned = OrientedBox(box.center, rotation, box.half_extents[order])
    return ObjectFrame(aligned, aligned.to_local(points))


@dataclass(frozen=True)
class CandidateRegion:
    """Points of one candidate region: ``indices`` into the cloud, their curvature and distance to the
    central plane; ``seed`` is the slice's extreme point the region was cropped around."""

    axis: str  # "y" or "z"
    side: int  # -1 (min) or +1 (max)
    seed_index: int
    indices: np.ndarray
    curvature: np.ndarray
    plane_distance: np.ndarray


def central_slice(frame: ObjectFrame, thickness: float) -> np.ndarray:
    """Indices of the points within ``thickness``/2 of the central plane x = 0."""
    return np.flatnonzero(np.abs(frame.local[:, 0]) <= 0.5 * thickness)


def voxel_thin(indices: np.ndarray, local: np.ndarray, voxel: float) -> np.ndarray:
    """Keep the first point of each occupied voxel (deterministic, keeps real points and normals)."""
    if len(indices) == 0:
        return indices
    keys = np.floor(local[indices] / voxel).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    return indices[np.sort(first)]


def surface_variation(points: np.ndarray, query: np.ndarray, radius: float) -> np.ndarray:
    """PCL's curvature λmin / (λ0 + λ1 + λ2) of each query point's radius neighbourhood in ``points``.

    Brute force on purpose: the regions are small (tens of queries against a few thousand points), so a
    dense distance matrix beats building a KD-tree over the whole cloud.
    """
    if len(query) == 0:
        return np.zeros(0)
    d2 = ((query[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    W = (d2 <= radius * radius).astype(float)  # (Q, M)
    n = W.sum(axis=1)
    s1 = W @ points  # (Q, 3)
    outer = (points[:, :, None] * points[:, None, :]).reshape(len(points), 9)
    s2 = (W @ outer).reshape(len(query), 3, 3)
    mean = s1 / np.maximum(n, 1)[:, None]
    cov = s2 / np.maximum(n, 1)[:, None, None] - mean[:, :, None] * mean[:, None, :]
    eig = np.linalg.eigvalsh(cov)
    trace = eig.sum(axis=1)
    curv = np.where(trace > 1e-18, np.abs(eig[:, 0]) / np.where(trace > 1e-18, trace, 1.0), 0.0)
    curv[n < 3] = 0.0
    return curv


def candidate_regions(frame: ObjectFrame, fingertip: float, slice_thickness: float, voxel: float,
                      curvature_radius: float) -> tuple[list[CandidateRegion], int]:
    """The four candidate regions (y-min, y-max, z-min, z-max); empty list when the slice is empty.

    Returns (regions, number of slice points).
    """
    local = frame.local
    slice_idx = central_slice(frame, slice_thickness)
    if len(slice_idx) == 0:
        return [], 0
    ext = frame.extents
    half = 0.5 * np.array([fingertip, min(fingertip, ext[1] / 3.0), min(fingertip, ext[2] / 3.0)])
    regions = []
    for axis_name, col in (("y", 1), ("z", 2)):
        coords = local[slice_idx, col]
        for side, pick in ((-1, int(np.argmin(coords))), (1, int(np.argmax(coords)))):
            seed = int(slice_idx[pick])
            offset = np.abs(local - local[seed])
            idx = np.flatnonzero(np.all(offset <= half, axis=1))
            kept = voxel_thin(idx, local, voxel)
            near = np.flatnonzero(np.all(offset <= half + curvature_radius, axis=1))
            curv = surface_variation(local[near], local[kept], curvature_radius)
            regions.append(CandidateRegion(axis_name, side, seed, kept, curv, np.abs(local[kept, 0])))
    return regions, len(slice_idx)
