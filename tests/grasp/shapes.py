"""Analytic object clouds with exact outward normals, standing on the table z = 0 of ``base``.

Points are sampled uniformly by area; ``view_from`` (one camera position or several) keeps only
the points whose normal faces a camera, which is exact visibility for the convex shapes used here (a partial view as the
wrist camera sees it). The face resting on the table is never sampled: no camera sees it.
"""

from __future__ import annotations

import numpy as np

from common.messages import Plane

OBJECT_XY = np.array([0.50, 0.0])  # docs/conventions.md
CAMERA = np.array([0.10, 0.0, 0.30])  # a wrist-camera position in front of and above the object


def scan_cameras(radius: float = 0.26, height: float = 0.30, spread_deg: float = 50.0) -> list[np.ndarray]:
    """Three wrist-camera positions like the paper's three scan poses: in front of the object (toward
    the arm's base) and ``spread_deg`` to either side; one registered view is their union."""
    out = []
    for az in (-spread_deg, 0.0, spread_deg):
        a = np.radians(180.0 + az)  # the base is at -x from the object
        out.append(np.array([OBJECT_XY[0] + radius * np.cos(a), OBJECT_XY[1] + radius * np.sin(a), height]))
    return out


def table_plane() -> Plane:
    return Plane(normal=np.array([0.0, 0.0, 1.0]), offset=0.0, center=np.array([0.4, 0.0, 0.0]))


def _finish(p: np.ndarray, n: np.ndarray, view_from, noise: float, rng, grazing: float = 0.0
            ) -> tuple[np.ndarray, np.ndarray]:
    """Keep what a camera of ``view_from`` sees: the cosine between the normal and the line of sight above
    ``grazing`` (a depth camera returns nothing from surfaces seen nearly edge-on); then add noise."""
    if view_from is not None:
        cams = np.atleast_2d(np.asarray(view_from, float))
        keep = np.zeros(len(p), bool)
        for cam in cams:
            sight = cam - p
            keep |= np.einsum("ij,ij->i", n, sight) > grazing * np.linalg.norm(sight, axis=1)
        p, n = p[keep], n[keep]
    if noise > 0:
        p = p + rng.normal(0.0, noise, p.shape)
    return p, n


def cylinder(radius: float, height: float, n: int = 20000, *, lying_along: np.ndarray | None = None,
             xy=OBJECT_XY, view_from=None, noise: float = 0.0, seed: int = 0, grazing: float = 0.0):
    """A closed cylinder. Standing (axis z, bottom on the table) unless ``lying_along`` gives a
    horizontal axis direction, then it lies on its side with the axis at height ``radius``."""
    rng = np.random.default_rng(seed)
    side_area = 2 * np.pi * radius * height
    cap_area = np.pi * radius**2
    n_caps = 1 if lying_along is None else 2
    probs = np.array([side_area] + [cap_area] * n_caps)
    counts = rng.multinomial(n, probs / probs.sum())
    # local frame: axis = local z, from 0 to height
    th = rng.uniform(0, 2 * np.pi, counts[0])
    zz = rng.uniform(0, height, counts[0])
    pts = [np.column_stack([radius * np.cos(th), radius * np.sin(th), zz])]
    nrm = [np.column_stack([np.cos(th), np.sin(th), np.zeros_like(th)])]
    for k, (h, s) in enumerate([(height, 1.0), (0.0, -1.0)][:n_caps]):
        m = counts[1 + k]
        r = radius * np.sqrt(rng.uniform(0, 1, m))
        a = rng.uniform(0, 2 * np.pi, m)
        pts.append(np.column_stack([r * np.cos(a), r * np.sin(a), np.full(m, h)]))
        nrm.append(np.tile([0.0, 0.0, s], (m, 1)))
    p, nn = np.vstack(pts), np.vstack(nrm)
    if lying_along is None:
        p = p + np.array([xy[0], xy[1], 0.0])
    else:
        a = np.asarray(lying_along, float)
        a = a / np.linalg.norm(a)
        b = np.cross([0.0, 0.0, 1.0], a)
        R = np.column_stack([b, np.array([0.0, 0.0, 1.0]), a])  # local x->b, y->up, z->axis
        p = (p - [0, 0, height / 2]) @ R.T + np.array([xy[0], xy[1], radius])
        nn = nn @ R.T
    return _finish(p, nn, view_from, noise, rng, grazing)


def box(size, n: int = 20000, *, yaw_deg: float = 0.0, xy=OBJECT_XY, view_from=None, noise: float = 0.0,
        seed: int = 0):
    """A box of ``size`` = (sx, sy, sz) standing on the table, rotated ``yaw_deg`` about z."""
    rng = np.random.default_rng(seed)
    s = np.asarray(size, float)
    faces = []  # (axis, sign)
    for axis in range(3):
        for sign in (-1.0, 1.0):
            if axis == 2 and sign < 0:
                continue  # the bottom face rests on the table
            faces.append((axis, sign))
    areas = np.array([np.prod(np.delete(s, ax)) for ax, _ in faces])
    counts = rng.multinomial(n, areas / areas.sum())
    pts, nrm = [], []
    for (ax, sign), m in zip(faces, counts, strict=True):
        q = rng.uniform(-0.5, 0.5, (m, 3)) * s
        q[:, ax] = 0.5 * sign * s[ax]
        nv = np.zeros((m, 3))
        nv[:, ax] = sign
        pts.append(q)
        nrm.append(nv)
    p, nn = np.vstack(pts), np.vstack(nrm)
    c, sn = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    R = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1.0]])
    p = p @ R.T + np.array([xy[0], xy[1], 0.5 * s[2]])
    return _finish(p, nn @ R.T, view_from, noise, rng)


# The test objects of the issue (sizes in metres)
def soup_can(**kw):
    return cylinder(0.034, 0.10, **kw)


def milk_carton(**kw):
    return box((0.07, 0.07, 0.19), **kw)


def cream_cheese(**kw):
    return box((0.104, 0.053, 0.024), **kw)


def lying_can(**kw):
    return cylinder(0.034, 0.10, lying_along=np.array([1.0, 0.0, 0.0]), **kw)
