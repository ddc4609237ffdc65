"""Completing an upright round object about its vertical axis: the arc of wall the scan poses could not see.

Why: the three scan poses see an upright can's wall over about 190° of azimuth (measured on a 7.65 cm can
in a 12-view physics scan: wall points from -100° to +90° about the direction of the arm's base); the far
arc is missing. The planner's box frame of a round footprint has no preferred turn (every rectangle around
a circle has the same area), so its region axes may end anywhere on the wall: one end on the seen wall,
the other just past the edge of the seen arc, where the central slice holds only the rim of the top face.
The face band there (a quarter of the half extent deep, about ±40° of arc) still catches seen wall, so the
end does not count as hidden and the mirror completion (completion.py) adds nothing; and even when it
mirrors, the top-down crop refits the box to the completed cloud, which may turn its axes away from the
mirrored face. Every pair then joins the top rim at one end to the middle of the wall at the other, a
tilted line (that can: 3,440 of 3,440 pairs ``grasp_line_not_horizontal``, and no grasp in the view).

What: a can, a jar or a bottle standing on its axis is a surface of revolution about a vertical line, so
any turn about that line maps its surface onto itself. The wall points (normals along the table) are cut
into height bands; each band's horizontal section is fitted with a circle (circle.py). When the bands are
round, about one vertical axis, and the seen wall covers enough of the circle for the fit to be trusted,
every unseen azimuth bin is filled with the seen wall of the bin nearest its antipode, turned about the
axis onto it (normals turned too), and appended as inferred points. The planner does this only when the
observed cloud (with its mirror completion) gave no grasp; grasps on the result report their inferred
contacts like mirrored ones. This is the rotational-symmetry counterpart of the planar mirror (Bohg et
al. 2011 discuss both); a box's sections are not circles, so it is never applied there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from common.geometry import rotation_about_line
from services.grasp.boxes import orthonormal_frame_from_axis
from services.grasp.circle import fit_circles_batched


@dataclass(frozen=True)
class RoundSection:
    """The vertical axis an upright round object's wall sections are centred on, and how much was seen."""

    axis_point: np.ndarray  # (3,) the axis where it meets the table plane (base)
    radius: float  # median radius of the round bands (m)
    rms: float  # largest RMS residual of a round band (m)
    bands: int  # height bands fitted as round
    seen_bins: np.ndarray  # (n_bins,) bool: azimuth bins holding seen wall
    bin_deg: float

    @property
    def seen_arc_deg(self) -> float:
        return float(np.count_nonzero(self.seen_bins)) * self.bin_deg

    def as_dict(self) -> dict[str, Any]:
        return {"axis_point": self.axis_point.tolist(), "radius": self.radius, "rms": self.rms,
                "bands": self.bands, "seen_arc_deg": self.seen_arc_deg}


@dataclass(frozen=True)
class Revolved:
    """The observed cloud with the unseen arc appended: rows ``[0, n_observed)`` are the input."""

    xyz: np.ndarray
    normals: np.ndarray
    n_observed: int
    section: RoundSection

    @property
    def n_inferred(self) -> int:
        return len(self.xyz) - self.n_observed

    def summary(self) -> dict[str, Any]:
        return {**self.section.as_dict(), "n_inferred": self.n_inferred}


def _wall(normals: np.ndarray, heights: np.ndarray, up: np.ndarray, wall_angle_deg: float,
          min_height: float) -> np.ndarray:
    """Mask of wall points: normals within ``wall_angle_deg`` of the table plane, above ``min_height``
    (the lowest millimetres mix the wall with the table's edge)."""
    return (np.abs(normals @ up) <= np.sin(np.radians(wall_angle_deg))) & (heights >= min_height)


def fit_vertical_axis(xyz: np.ndarray, normals: np.ndarray, up: np.ndarray, offset: float, *,
                      wall_angle_deg: float = 30.0, band_height: float = 0.01, tolerance: float = 0.002,
                      min_seen_arc_deg: float = 120.0, bin_deg: float = 10.0, min_band_points: int = 30,
                      min_height: float = 0.005) -> RoundSection | None:
    """The vertical axis the wall's horizontal sections are circles about, or None when they are not.

    Round means: at least half the height bands holding ``min_band_points`` wall points fit a circle with
    an RMS residual within ``tolerance``, the round bands' centres lie within ``tolerance`` of their median
    (one vertical axis, not a tilted or lying body), and the seen wall spans at least ``min_seen_arc_deg``
    of azimuth about it (a short arc fits any circle). ``up``/``offset``: the table plane, normal toward
    the object."""
    heights = xyz @ up + offset
    wall = _wall(normals, heights, up, wall_angle_deg, min_height)
    if np.count_nonzero(wall) < min_band_points:
        return None
    basis = orthonormal_frame_from_axis(up)[:, 1:]  # two horizontal directions
    flat = xyz[wall] @ basis
    band = np.floor((heights[wall] - min_height) / band_height).astype(np.int64)
    counts = np.bincount(band)
    full = np.flatnonzero(counts >= min_band_points)
    if len(full) == 0:
        return None
    keep = np.isin(band, full)
    labels = np.searchsorted(full, band[keep])
    centres, radii, ok = fit_circles_batched(flat[keep], labels, len(full))
    residual = np.abs(np.linalg.norm(flat[keep] - centres[labels], axis=1) - radii[labels])
    rms = np.sqrt(np.bincount(labels, residual**2, len(full)) / np.maximum(np.bincount(labels, None, len(full)), 1))
    round_ = ok & (rms <= tolerance)
    if 2 * np.count_nonzero(round_) < len(full):
        return None
    centre = np.median(centres[round_], axis=0)
    if np.linalg.norm(centres[round_] - centre, axis=1).max() > tolerance:
        return None
    rel = flat - centre
    azimuth = np.degrees(np.arctan2(rel[:, 1], rel[:, 0])) % 360.0
    n_bins = int(round(360.0 / bin_deg))
    per_bin = np.bincount((azimuth // bin_deg).astype(np.int64) % n_bins, minlength=n_bins)
    # a bin counts as seen when it holds a fair share of wall: the grazing edge of the seen arc holds a few
    # stray points, which would otherwise leave that bin nearly empty
    seen = per_bin >= max(2.0, 0.25 * float(np.median(per_bin[per_bin > 0])))
    if np.count_nonzero(seen) * bin_deg < min_seen_arc_deg:
        return None
    axis_point = -offset * up + basis @ centre
    return RoundSection(axis_point, float(np.median(radii[round_])), float(rms[round_].max()),
                        int(np.count_nonzero(round_)), seen, 360.0 / n_bins)


def revolve_unseen_arc(xyz: np.ndarray, normals: np.ndarray, up: np.ndarray, offset: float,
                       section: RoundSection, wall_angle_deg: float = 30.0, min_height: float = 0.005
                       ) -> Revolved:
    """Fill each unseen azimuth bin of ``section`` with the seen wall of the bin nearest its antipode,
    turned about the vertical axis onto it (see the module doc). Nothing is appended when every bin is seen."""
    heights = xyz @ up + offset
    wall = np.flatnonzero(_wall(normals, heights, up, wall_angle_deg, min_height))
    basis = orthonormal_frame_from_axis(up)[:, 1:]
    rel = (xyz[wall] - section.axis_point) @ basis
    n_bins = len(section.seen_bins)
    bins = (np.degrees(np.arctan2(rel[:, 1], rel[:, 0])) % 360.0 // section.bin_deg).astype(np.int64) % n_bins
    seen = np.flatnonzero(section.seen_bins)
    extra_xyz, extra_normals = [], []
    for b in np.flatnonzero(~section.seen_bins):
        antipode = (b + n_bins // 2) % n_bins
        gap = np.abs((seen - antipode + n_bins // 2) % n_bins - n_bins // 2)  # circular distance in bins
        source = int(seen[np.argmin(gap)])
        rows = wall[bins == source]
        T = rotation_about_line(up, section.axis_point, np.radians((b - source) * section.bin_deg))
        extra_xyz.append(xyz[rows] @ T[:3, :3].T + T[:3, 3])
        extra_normals.append(normals[rows] @ T[:3, :3].T)
    if not extra_xyz:
        return Revolved(xyz, normals, len(xyz), section)
    return Revolved(np.concatenate([xyz, *extra_xyz]), np.concatenate([normals, *extra_normals]), len(xyz), section)
