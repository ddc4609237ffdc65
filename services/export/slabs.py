"""Convex parts by horizontal slabs (and sectors of a slab), each grown while its hull hugs the surface.

The objects an export sees stand on the table and are mostly prisms along the vertical: a carton's body and
gable top, a can's body and the rim around its recessed lid. Cut into horizontal slabs, each slab's hull is
close to the surface except where a slab's cross-section is concave, and there the slab is cut: into halves
or quarters (notches on its centre lines), a grid, or sectors around its centre (a can's rim is a ring around
the lid's pocket: each sector's hull spans only a short chord of it).
Every part is measured against the mesh while it is built (its hull's surface outside the mesh), so the
result is checked, not hoped for; it costs a second or two of CPU and is the same for the same mesh, where
CoACD's tree search took 3-16 s on nearly identical carton meshes and left parts 2.8 mm out on one, 8 mm on
the other. ``collision.collision_parts`` keeps whichever of hull, slabs and CoACD stands out least.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d
from scipy.spatial import ConvexHull, QhullError

#: The finest slab (m): about the surface's own cell (Poisson ~1.6 mm), finer slabs hold no new vertices.
STEP_M = 0.002
#: Parts are built to stand out at most this fraction of the tolerance: the check samples a hull's surface more
#: sparsely than the final measure (``collision.deviation_figures``), whose 99.5th percentile comes out higher.
MARGIN = 0.9
#: Samples on a candidate hull's surface when checking it (its 99.5th percentile outside the mesh is used).
CHECK_SAMPLES = 1500


class _Checker:
    """How far a candidate hull stands out of the mesh (m): its surface's 99.5th percentile outside it."""

    def __init__(self, mesh: o3d.geometry.TriangleMesh, samples: int = CHECK_SAMPLES) -> None:
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
        self.samples = samples

    def __call__(self, pts: np.ndarray) -> float:
        sample = hull_samples(pts, self.samples)
        if sample is None:
            return 0.0  # flat or too few points: no volume to stand out
        d = self.scene.compute_signed_distance(o3d.core.Tensor(sample.astype(np.float32))).numpy()
        outside = d[d > 0]
        return float(np.percentile(outside, 99.5)) if outside.size else 0.0


def hull_samples(pts: np.ndarray, count: int, seed: int = 0) -> np.ndarray | None:
    """``count`` points spread uniformly over the surface of ``pts``' convex hull (None when it has no volume).

    Seeded: the same part gives the same samples, so how far it stands out is the same figure on every run.
    """
    try:
        hull = ConvexHull(pts)
    except (QhullError, ValueError):
        return None
    tri = pts[hull.simplices]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if area.sum() <= 0:
        return None
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(tri), size=count, p=area / area.sum())
    u, v = rng.random((2, count))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tri[pick]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


Plane = tuple[np.ndarray, float]  # a vertical half-space n . xy >= c


class _Solid:
    """The closed mesh's points clipped to a slab and vertical half-spaces: its vertices there and its edges'
    crossings of the clipping planes (a hull of them is the clipped solid, up to the corners where two
    clipping planes meet the surface, which fall just inside it)."""

    def __init__(self, mesh: o3d.geometry.TriangleMesh) -> None:
        self.v = np.asarray(mesh.vertices, dtype=np.float64)
        t = np.asarray(mesh.triangles, dtype=np.int64)
        e = np.unique(np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1), axis=0)
        self.a, self.b = self.v[e[:, 0]], self.v[e[:, 1]]

    def _crossings(self, sa: np.ndarray, sb: np.ndarray) -> np.ndarray:
        """Points where edges cross the level 0 of a linear function with values ``sa``, ``sb`` at their ends."""
        cross = sa * sb < 0
        s = sa[cross] / (sa[cross] - sb[cross])
        return self.a[cross] + s[:, None] * (self.b[cross] - self.a[cross])

    def clip(self, z0: float, z1: float, planes: list[Plane] = ()) -> np.ndarray:
        """The points whose hull is the solid between heights ``z0`` and ``z1`` inside ``planes``."""
        pts = [self.v, self._crossings(self.a[:, 2] - z0, self.b[:, 2] - z0),
               self._crossings(self.a[:, 2] - z1, self.b[:, 2] - z1)]
        pts += [self._crossings(self.a[:, :2] @ n - c, self.b[:, :2] @ n - c) for n, c in planes]
        p = np.vstack(pts)
        keep = (p[:, 2] >= z0 - 1e-9) & (p[:, 2] <= z1 + 1e-9)
        for n, c in planes:
            keep &= p[:, :2] @ n >= c - 1e-9
        return p[keep]


def _grid(lo: np.ndarray, hi: np.ndarray, nx: int, ny: int) -> list[list[Plane]]:
    """Cells of an ``nx`` x ``ny`` grid over the box ``lo``-``hi`` (x-y), as half-space lists."""
    xs, ys = np.linspace(lo[0], hi[0], nx + 1)[1:-1], np.linspace(lo[1], hi[1], ny + 1)[1:-1]
    ex, ey = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    cells = []
    for i in range(nx):
        for j in range(ny):
            cell: list[Plane] = []
            if i > 0:
                cell.append((ex, float(xs[i - 1])))
            if i < nx - 1:
                cell.append((-ex, -float(xs[i])))
            if j > 0:
                cell.append((ey, float(ys[j - 1])))
            if j < ny - 1:
                cell.append((-ey, -float(ys[j])))
            cells.append(cell)
    return cells


def _sectors(centre: np.ndarray, count: int) -> list[list[Plane]]:
    """``count`` equal wedges around ``centre`` (x-y), as pairs of half-spaces."""
    out = []
    for k in range(count):
        lo, hi = 2 * np.pi * k / count, 2 * np.pi * (k + 1) / count
        n_lo, n_hi = np.array([-np.sin(lo), np.cos(lo)]), np.array([np.sin(hi), -np.cos(hi)])
        out.append([(n_lo, float(n_lo @ centre)), (n_hi, float(n_hi @ centre))])
    return out


def _layouts(pts: np.ndarray) -> list[list[list[Plane]]]:
    """Ways to cut a slab, fewest pieces first: whole, halves, quarters (the notches of a carton's gable top
    fall on its centre lines), then sectors around the centre (a can's rim around its lid) and a finer grid."""
    lo, hi = pts[:, :2].min(axis=0), pts[:, :2].max(axis=0)
    centre = 0.5 * (lo + hi)
    return [[[]], _grid(lo, hi, 2, 1), _grid(lo, hi, 1, 2), _grid(lo, hi, 2, 2), _grid(lo, hi, 3, 3),
            _sectors(centre, 8), _grid(lo, hi, 4, 4), _sectors(centre, 16), _sectors(centre, 32)]


def _hull_points(pts: np.ndarray) -> np.ndarray | None:
    if len(pts) < 4 or np.ptp(pts, axis=0).min() < 1e-5:
        return None
    try:
        return pts[ConvexHull(pts).vertices]
    except (QhullError, ValueError):
        return None


def _grow(good: float, zmax: float, step_m: float, holds) -> float:  # noqa: ANN001
    """The highest top (to ``step_m``) above ``good`` for which ``holds(top)``: gallop up, bisect the last stride.

    A taller slab's hull contains a shorter one's, so once a top fails the ones above it fail too (up to
    the sampling of the check).
    """
    stride, bad = step_m, None
    while good < zmax - 1e-9:
        trial = min(good + stride, zmax)
        if not holds(trial):
            bad = trial
            break
        good, stride = trial, 2 * stride
    while bad is not None and bad - good > step_m:
        mid = 0.5 * (good + bad)
        if holds(mid):
            good = mid
        else:
            bad = mid
    return good


def slab_parts(mesh: o3d.geometry.TriangleMesh, tolerance_m: float, step_m: float = STEP_M
               ) -> list[np.ndarray] | None:
    """Convex parts (hull vertices) of the closed ``mesh`` (object frame, z up), bottom to top: each slab takes
    the fewest pieces (``_layouts``) whose hulls stand out at most ``MARGIN`` x ``tolerance_m`` one step thick,
    then grows upward while that layout's pieces stay within it. None as soon as no layout holds one step
    thick (a cross-section too intricate for straight cuts, such as a carton's folded top: CoACD's case).
    """
    tolerance_m *= MARGIN
    solid, check = _Solid(mesh), _Checker(mesh)
    zmin, zmax = float(solid.v[:, 2].min()), float(solid.v[:, 2].max())

    def worst(z0: float, z1: float, layout: list[list[Plane]]) -> float:
        return max((check(p) for p in (solid.clip(z0, z1, cell) for cell in layout) if len(p) >= 4), default=0.0)

    parts: list[np.ndarray] = []
    z0 = zmin
    while z0 < zmax - 1e-9:
        z1 = min(z0 + step_m, zmax)
        scored = []
        for layout in _layouts(solid.clip(z0, z1)):
            d = worst(z0, z1, layout)
            scored.append((d, layout))
            if d <= tolerance_m:
                break
        d, layout = scored[-1]
        if d > tolerance_m:
            return None
        good = _grow(z1, zmax, step_m, lambda z, z0=z0, layout=layout: worst(z0, z, layout) <= tolerance_m)
        parts += [h for h in (_hull_points(solid.clip(z0, good, cell)) for cell in layout) if h is not None]
        z0 = good
    return parts
