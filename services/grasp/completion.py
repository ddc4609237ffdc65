"""Completing the side face the scan poses cannot see, by mirror symmetry about the object's box.

Why: the three scan poses look at the object from the arm's side, within about ±22° of azimuth. A box
turned away from those directions (30°, 60°, 90°, ... for the cream cheese, any turn that is not a
multiple of 90° for the square cartons) never shows two opposite side faces: one view holds its top,
one or two adjacent side faces, and nothing of the faces turned away. GeoGrasp pairs observed points
only, so on such a view the central slice's extreme point on the hidden side is an edge (the far edge of
the top face, or the vertical edge where the seen faces end): every pair is then tilted
(``grasp_line_not_horizontal``) or has an edge normal across the grasp line (``not_antipodal``), and no
grasp survives, view after view, re-scan after re-scan (the scan poses do not change with the turn).

What: along each horizontal axis of the table-aligned box on which grasp regions are sought (the
frame's y and z), count the points of a face at each end (points within ``band`` of the box side whose
normals lie within ``face_angle`` of the axis). When one end has (almost) no face while the other has
one, the seen face is mirrored about the box's central plane across that axis, normals mirrored too,
and appended to the cloud as inferred points. The box itself is not refitted: the footprint is bounded
by what is seen whole, the top face and the adjacent side faces (a convex prism shows every face it
shows at all in full), so the mirrored face lands on the box side. This is the planar-symmetry
completion of Bohg et al. 2011 ("Mind the gap: robotic grasping under incomplete observation"),
restricted to planes perpendicular to the table through the box centre; the inferred contact is exact
for boxes and cans and an assumption for other shapes, which is why grasps report how many of their
contacts are inferred.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from services.grasp.candidates import ObjectFrame

AXES = (("y", 1), ("z", 2))
"""The frame's region axes (GeoGrasp's candidate regions lie at the ends of y and z, never of x)."""


@dataclass(frozen=True)
class SideFaces:
    """Face points found at each end of one box axis and what was decided."""

    axis: str
    points: tuple[int, int]  # face points at the (min, max) end
    hidden_side: int  # -1 / +1: that end was not seen; 0: both seen, or neither
    mirrored: int  # inferred points appended for this axis
    status: str  # "seen" (both ends), "completed", "hidden" (not completed), "unseen" (no face at either end)

    def as_dict(self) -> dict[str, Any]:
        return {"axis": self.axis, "status": self.status, "face_points": list(self.points),
                "hidden_side": self.hidden_side, "mirrored_points": self.mirrored}


@dataclass(frozen=True)
class Completion:
    """The cloud with its inferred points appended: rows ``[0, n_observed)`` are the input, the rest
    mirrored. ``local`` is the same cloud in the (unchanged) box frame."""

    xyz: np.ndarray
    normals: np.ndarray
    local: np.ndarray
    n_observed: int
    sides: list[SideFaces] = field(default_factory=list)

    @property
    def n_inferred(self) -> int:
        return len(self.xyz) - self.n_observed

    @property
    def completed_axes(self) -> list[str]:
        return [s.axis for s in self.sides if s.mirrored]

    @property
    def completed_cols(self) -> list[int]:
        """Box-frame columns of the completed axes (y = 1, z = 2)."""
        cols = dict(AXES)
        return [cols[name] for name in self.completed_axes]

    @property
    def incomplete_sides(self) -> list[SideFaces]:
        """Axes left with an end unseen: completion disabled, or no face at either end to mirror."""
        return [s for s in self.sides if s.status in ("hidden", "unseen")]

    def frame(self, observed: ObjectFrame) -> ObjectFrame:
        """The observed box frame holding the completed cloud."""
        return ObjectFrame(observed.box, self.local)

    def summary(self) -> dict[str, Any]:
        return {"n_observed": self.n_observed, "n_inferred": self.n_inferred,
                "completed_axes": self.completed_axes, "sides": [s.as_dict() for s in self.sides]}


def horizontal_axes(frame: ObjectFrame, up: np.ndarray, max_cos: float = 0.5) -> list[tuple[str, int]]:
    """The region axes (y, z) of ``frame`` that lie along the table (|cos| to the normal < ``max_cos``).

    A region axis along the table normal pairs the object's top with its lowest seen points: such a
    grasp line is vertical, which neither a horizontal nor a downward hand can close on."""
    return [(name, col) for name, col in AXES if abs(float(frame.rotation[:, col] @ up)) < max_cos]


def find_side_faces(local: np.ndarray, local_normals: np.ndarray, half_extent: float, col: int,
                    band: float, cos_face: float) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the face points at the min and max end of column ``col``: within ``band`` of the box
    side and with a normal within the face angle of the axis (the normal's sign is not trusted)."""
    c = local[:, col]
    along = np.abs(local_normals[:, col]) >= cos_face
    return along & (c <= -half_extent + band), along & (c >= half_extent - band)


def complete_hidden_sides(frame: ObjectFrame, xyz: np.ndarray, normals: np.ndarray, up: np.ndarray, *,
                          band: float, face_angle_deg: float, hidden_ratio: float, min_face_points: int,
                          enabled: bool = True, spacing: float = 0.0) -> Completion:
    """Mirror the seen face onto each hidden end of the horizontal region axes (see the module doc).

    An end is hidden when it has at most ``hidden_ratio`` times the face points of the other end and
    the other end has at least ``min_face_points``. ``band`` is the minimum depth of the face band
    (a quarter of the half extent when larger, for curved sides). With ``enabled`` False the sides are
    still assessed (so a plan can say a side was not seen) but nothing is added. ``spacing`` > 0 keeps
    about one mirrored point per ``spacing``² of face (an even stride through the face points): the
    planner thins its regions and curvature neighbourhoods at that scale anyway, and a dense scan's face
    would otherwise add half as many points again.
    """
    local_normals = normals @ frame.rotation
    cos_face = float(np.cos(np.radians(face_angle_deg)))
    sides: list[SideFaces] = []
    extra_local, extra_normals = [], []
    for name, col in horizontal_axes(frame, up):
        half = 0.5 * float(frame.extents[col])
        lo, hi = find_side_faces(frame.local, local_normals, half, col, max(band, 0.25 * half), cos_face)
        counts = (int(np.count_nonzero(lo)), int(np.count_nonzero(hi)))
        hidden, seen_mask = 0, None
        if counts[1] >= min_face_points and counts[0] <= hidden_ratio * counts[1]:
            hidden, seen_mask = -1, hi
        elif counts[0] >= min_face_points and counts[1] <= hidden_ratio * counts[0]:
            hidden, seen_mask = 1, lo
        added, status = 0, "seen"
        if seen_mask is None and max(counts) < min_face_points:
            status = "unseen"
        elif seen_mask is not None and not enabled:
            status = "hidden"
        elif seen_mask is not None:
            status = "completed"
            seen_rows = np.flatnonzero(seen_mask)
            if spacing > 0:  # about one point per spacing² of face: a stride, not a voxel sort (it is hot)
                others = [c for c in range(3) if c != col]
                area = float(np.prod(frame.extents[others]))
                seen_rows = seen_rows[:: max(1, int(len(seen_rows) * spacing**2 / max(area, 1e-12)))]
            loc = frame.local[seen_rows].copy()
            loc[:, col] *= -1.0  # the box centre is the local origin: a sign flip mirrors about its plane
            nrm = local_normals[seen_rows].copy()
            nrm[:, col] *= -1.0
            extra_local.append(loc)
            extra_normals.append(nrm)
            added = len(loc)
        sides.append(SideFaces(name, counts, hidden, added, status))
    if not extra_local:
        return Completion(xyz, normals, frame.local, len(xyz), sides)
    loc = np.concatenate(extra_local)
    nrm = np.concatenate(extra_normals) @ frame.rotation.T
    return Completion(np.concatenate([xyz, frame.to_base(loc)]), np.concatenate([normals, nrm]),
                      np.concatenate([frame.local, loc]), len(xyz), sides)
