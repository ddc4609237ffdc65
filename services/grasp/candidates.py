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
from scipy.spatial import cKDTree

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
    normals: np.ndarray | None = None
    """Normals estimated from the same neighbourhood as the curvature (in the cloud's frame); None =
    use the input normals."""
    source: str = "all"
    """"all": cut from the whole cloud; "observed": from the observed rows only (see candidate_regions)."""


def central_slice(frame: ObjectFrame, thickness: float) -> np.ndarray:
    """Indices of the points within ``thickness``/2 of the central plane x = 0."""
    return np.flatnonzero(np.abs(frame.local[:, 0]) <= 0.5 * thickness)


def voxel_keys(local: np.ndarray, voxel: float) -> np.ndarray:
    """One int64 key per point naming its voxel (1-D keys sort far faster than ``unique(axis=0)``)."""
    cells = np.floor(local / voxel).astype(np.int64)
    cells -= cells.min(axis=0)
    dims = cells.max(axis=0) + 1
    return (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]


def voxel_thin(indices: np.ndarray, local: np.ndarray, voxel: float) -> np.ndarray:
    """Keep the first point of each occupied voxel (deterministic, keeps real points and normals)."""
    if len(indices) == 0:
        return indices
    _, first = np.unique(voxel_keys(local[indices], voxel), return_index=True)
    return indices[np.sort(first)]


def local_surface(points: np.ndarray, query: np.ndarray, radius: float, k: int = 20
                  ) -> tuple[np.ndarray, np.ndarray]:
    """PCL's normal estimation at each query point: (curvature λmin / (λ0 + λ1 + λ2), unit normal =
    the eigenvector of λmin) of its neighbourhood in ``points``.

    The neighbourhood is the ``k`` nearest points within ``radius`` (a KD-tree over the small patch
    around the regions, not over the whole cloud). The normal's sign is arbitrary (the ranking uses
    |cos|).
    """
    if len(query) == 0:
        return np.zeros(0), np.zeros((0, 3))
    if len(points) < 3:
        return np.zeros(len(query)), np.tile([0.0, 0.0, 1.0], (len(query), 1))
    origin = query.mean(axis=0)  # centred coordinates keep the second moments precise
    P, Q = points - origin, query - origin
    k = min(k, len(P))
    dist, idx = cKDTree(P).query(Q, k=k, distance_upper_bound=radius)
    dist = dist.reshape(len(Q), k)
    valid = np.isfinite(dist)
    idx = np.where(valid, idx.reshape(len(Q), k), 0)
    w = valid.astype(float)[:, :, None]
    n = w.sum(axis=1)  # (Q, 1)
    nb = P[idx] * w  # (Q, k, 3)
    mean = nb.sum(axis=1) / np.maximum(n, 1.0)
    cov = np.einsum("qki,qkj->qij", nb, P[idx]) / np.maximum(n, 1.0)[:, :, None] \
        - mean[:, :, None] * mean[:, None, :]
    eig, vec = np.linalg.eigh(cov)
    trace = eig.sum(axis=1)
    curv = np.abs(eig[:, 0]) / np.where(trace > 1e-18, trace, 1.0)
    degenerate = (n[:, 0] < 3) | (trace <= 1e-18)
    curv[degenerate] = 0.0
    normals = vec[:, :, 0].copy()
    normals[degenerate] = np.nan  # callers fall back to the input normal there
    return curv, normals


def surface_variation(points: np.ndarray, query: np.ndarray, radius: float, k: int = 20) -> np.ndarray:
    """Curvature only (see :func:`local_surface`)."""
    return local_surface(points, query, radius, k)[0]


def extreme_point(slice_local: np.ndarray, col: int, side: int, tolerance: float) -> int:
    """Index of the slice's extreme point along column ``col`` (side -1: min, +1: max).

    On a flat face every point is 'extreme' to within noise, and the plain argmax lands anywhere on it
    (two seeds at different heights give only tilted pairs). So among the points within ``tolerance``
    of the extreme, take the one nearest the box's centre line in the other coordinate.
    """
    coords = side * slice_local[:, col]
    near = np.flatnonzero(coords >= coords.max() - tolerance)
    other = 3 - col  # 1 <-> 2
    return int(near[np.argmin(np.abs(slice_local[near, other]))])


def candidate_regions(frame: ObjectFrame, fingertip: float, slice_thickness: float, voxel: float,
                      curvature_radius: float, seed_tolerance: float = 0.002, refit_normals: bool = True,
                      axes: list[tuple[str, int]] | tuple[tuple[str, int], ...] = (("y", 1), ("z", 2)),
                      n_observed: int | None = None,
                      observed_axes: list[tuple[str, int]] | tuple[tuple[str, int], ...] = ()
                      ) -> tuple[list[CandidateRegion], int]:
    """The candidate regions at the min and max end of each of ``axes`` (default y and z: y-min, y-max,
    z-min, z-max); empty list when the slice is empty.

    With ``n_observed`` (rows from there on are inferred points), the regions of ``observed_axes`` are
    cut a second time from the observed rows alone (source "observed", seeds, crops and curvature
    neighbourhoods all without inferred points), sharing the slab and the masks' setup with the first cut.

    Returns (regions, number of slice points).
    """
    local = frame.local
    slice_idx = central_slice(frame, slice_thickness)
    if len(slice_idx) == 0:
        return [], 0
    ext = frame.extents
    half = 0.5 * np.array([fingertip, min(fingertip, ext[1] / 3.0), min(fingertip, ext[2] / 3.0)])
    # every region lies in the slab |x| <= half_x (+ the curvature radius): mask the cloud once
    slab = np.flatnonzero(np.abs(local[:, 0]) <= half[0] + curvature_radius)
    slab_local = local[slab]
    jobs = [(name, col, "all") for name, col in axes]
    if n_observed is not None and len(observed_axes):
        jobs += [(name, col, "observed") for name, col in observed_axes]
        slab_seen = slab < n_observed
        slice_seen = slice_idx[slice_idx < n_observed]
    found = []
    near_masks = {"all": np.zeros(len(slab), bool), "observed": np.zeros(len(slab), bool)}
    for axis_name, col, source in jobs:
        seeds = slice_idx if source == "all" else slice_seen
        if len(seeds) == 0:
            continue
        if source == "observed" and not any(f[3].max(initial=-1) >= n_observed for f in found
                                            if f[0] == axis_name and f[4] == "all"):
            continue  # the whole-cloud regions of this axis hold no inferred point: same cut
        for side in (-1, 1):
            seed = int(seeds[extreme_point(local[seeds], col, side, seed_tolerance)])
            # the band along the axis first (one column), then the full box test on the few points left
            band = np.flatnonzero(np.abs(slab_local[:, col] - local[seed, col]) <= half[col] + curvature_radius)
            offset = np.abs(slab_local[band] - local[seed])
            inside = np.all(offset <= half, axis=1)
            near = np.all(offset <= half + curvature_radius, axis=1)
            if source == "observed":
                inside &= slab_seen[band]
                near &= slab_seen[band]
            near_masks[source][band[near]] = True
            found.append((axis_name, side, seed, voxel_thin(slab[band[inside]], local, voxel), source))
    # one curvature pass per source for all its regions; the neighbourhood is thinned so k neighbours
    # span the whole radius whatever the density
    curvature: dict[str, tuple[np.ndarray, np.ndarray | None]] = {}
    for source, mask in near_masks.items():
        kept = [f[3] for f in found if f[4] == source]
        if not kept:
            continue
        near = voxel_thin(slab[mask], local, 0.25 * curvature_radius)
        curv, normals_local = local_surface(local[near], local[np.concatenate(kept)], curvature_radius)
        curvature[source] = (curv, normals_local @ frame.rotation.T if refit_normals else None)
    regions, starts = [], dict.fromkeys(curvature, 0)
    for axis_name, side, seed, kept, source in found:
        start = starts[source]
        span = slice(start, start + len(kept))
        starts[source] = start + len(kept)
        curv, normals = curvature[source]
        regions.append(CandidateRegion(axis_name, side, seed, kept, curv[span], np.abs(local[kept, 0]),
                                       None if normals is None else normals[span], source))
    return regions, len(slice_idx)
