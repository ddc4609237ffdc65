"""Stray points: single depth returns far from every other point of the object's cloud.

Why: the planner's box frame spans every point (``boxes.table_aligned_box`` takes the extremes), so one
flying pixel a few millimetres beyond a face moves that face's end of the box, the face's points fall out
of the band the hidden-side completion counts, and a face seen with thousands of points is taken for a
hidden one (a 5.4 cm slab: 61 face points counted instead of ~6,600, every grasp line tilted, no grasp).
A point of a sampled surface has its few nearest neighbours at about the cloud's own spacing (an edge
point at ~1.4x it); a stray return has none nearby. The yardstick is the cloud's own density, so the
test holds at any voxel size or camera distance.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

NEIGHBOURS = 4
"""A point is kept when its 4th-nearest neighbour is near: a speck of up to four returns is stray."""
SPACING_FACTOR = 2.5
"""...near meaning within this multiple of the cloud's median 4th-neighbour distance (a face's edge point
reaches ~1.4x it; a return 6-7 mm off a face sampled at ~1 mm, 3.2-4x)."""


def stray_mask(xyz: np.ndarray, neighbours: int = NEIGHBOURS, factor: float = SPACING_FACTOR) -> np.ndarray:
    """True for each point whose ``neighbours``-th nearest neighbour lies farther than ``factor`` times the
    cloud's median such distance. A cloud too small to judge has no stray point."""
    xyz = np.asarray(xyz, dtype=np.float64)
    if len(xyz) <= 4 * neighbours:
        return np.zeros(len(xyz), dtype=bool)
    dist, _ = cKDTree(xyz).query(xyz, k=neighbours + 1)  # the first neighbour is the point itself
    kth = dist[:, neighbours]
    return kth > factor * float(np.median(kth))
