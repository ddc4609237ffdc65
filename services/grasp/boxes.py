"""Oriented boxes: the separating-axis overlap test, point containment, and the table-aligned box.

The collision filter of the paper models the table and the two gripper pads as boxes; two boxes are
disjoint exactly when some axis separates their projections. For two boxes the 15 candidate axes are
the 3 face normals of each and the 9 cross products of their edges (Gottschalk et al., OBBTree, 1996).
No library we ship exposes a bare OBB-OBB test on numpy boxes cheaply (coal would need shape objects
per call), so it is written here; the tests check it against coal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.footprint import min_area_rectangle


@dataclass(frozen=True)
class OrientedBox:
    """A box: ``center`` (3,), ``rotation`` (3, 3) whose columns are the box axes in the parent frame,
    ``half_extents`` (3,) along those axes."""

    center: np.ndarray
    rotation: np.ndarray
    half_extents: np.ndarray

    @classmethod
    def from_extents(cls, center: np.ndarray, rotation: np.ndarray, extents: np.ndarray) -> OrientedBox:
        return cls(np.asarray(center, float).reshape(3), np.asarray(rotation, float).reshape(3, 3),
                   0.5 * np.asarray(extents, float).reshape(3))

    def corners(self) -> np.ndarray:
        """The 8 corners (8, 3): the planner's lowest pad point is the lowest of them."""
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
        return self.center + (signs * self.half_extents) @ self.rotation.T

    def to_local(self, points: np.ndarray) -> np.ndarray:
        return (np.asarray(points, float) - self.center) @ self.rotation


def boxes_overlap(a: OrientedBox, b: OrientedBox, eps: float = 1e-12) -> bool:
    """True when the boxes intersect (touching counts as overlap); separating-axis test on 15 axes."""
    Ra, Rb = a.rotation, b.rotation
    ea, eb = a.half_extents, b.half_extents
    R = Ra.T @ Rb  # b's axes in a's frame
    t = Ra.T @ (b.center - a.center)  # centre offset in a's frame
    absR = np.abs(R) + eps  # eps guards near-parallel edges whose cross products vanish
    # a's face normals
    if np.any(np.abs(t) > ea + absR @ eb):
        return False
    # b's face normals
    if np.any(np.abs(t @ R) > ea @ absR + eb):
        return False
    # edge-edge cross products A_i x B_j
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            ra = ea[i1] * absR[i2, j] + ea[i2] * absR[i1, j]
            rb = eb[j1] * absR[i, j2] + eb[j2] * absR[i, j1]
            if abs(t[i2] * R[i1, j] - t[i1] * R[i2, j]) > ra + rb:
                return False
    return True


def points_in_box(box: OrientedBox, points: np.ndarray) -> np.ndarray:
    """Boolean mask of the points inside (or on) the box."""
    local = box.to_local(points)
    return np.all(np.abs(local) <= box.half_extents, axis=1)


def orthonormal_frame_from_axis(axis: np.ndarray) -> np.ndarray:
    """A right-handed rotation whose first column is ``axis`` (normalised); the others are arbitrary."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    b = cross3(a, helper)
    b /= np.sqrt(b @ b)
    return np.column_stack([a, b, cross3(a, b)])


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two 3-vectors without np.cross's general-axis overhead (hot in the planner)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def table_aligned_box(points: np.ndarray, up: np.ndarray) -> OrientedBox:
    """The object's bounding box with one axis along the table normal ``up`` and the other two the
    minimum-area rectangle of its footprint.

    This is the paper's fix to GeoGrasp: a plain PCA axis runs along a box's diagonal, whereas this box
    is always parallel or perpendicular to the table. Columns are (up, u, v) in that order; callers
    reorder them by side length.
    """
    frame = orthonormal_frame_from_axis(up)
    local = np.asarray(points, float) @ frame  # (h, a, b)
    center2, axes2, sides2 = min_area_rectangle(local[:, 1:])
    h_lo, h_hi = local[:, 0].min(), local[:, 0].max()
    u = frame[:, 1:] @ axes2[:, 0]
    v = frame[:, 1:] @ axes2[:, 1]
    rotation = np.column_stack([frame[:, 0], u, v])
    if np.linalg.det(rotation) < 0:
        rotation[:, 2] *= -1
    center = frame @ np.array([0.5 * (h_lo + h_hi), center2[0], center2[1]])
    return OrientedBox(center, rotation, 0.5 * np.array([h_hi - h_lo, sides2[0], sides2[1]]))
