"""Least-squares circle fits and the object-centre estimate the turn poses rotate about.

The paper (II-B.4) finds the object's centre as the mean of circle fits to random yz-slices of the
axis-aligned object, fitting each slice by least squares. We do the algebraic (Kåsa) fit, which is a
single linear solve, then a few Gauss-Newton steps on the geometric residual |p - c| - r: the algebraic
fit alone is biased toward smaller circles on the partial arcs a single view sees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CircleFit:
    center: np.ndarray  # (2,)
    radius: float
    rms: float  # RMS of the geometric residuals
    n: int


def fit_circle_2d(points: np.ndarray, refine_iterations: int = 5) -> CircleFit | None:
    """Fit a circle to (N, 2) points; None when they do not define one (fewer than 3 or collinear)."""
    p = np.asarray(points, float)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 3 or not np.all(np.isfinite(p)):
        return None
    offset = p.mean(axis=0)
    q = p - offset  # centring and scaling keep the normal equations well conditioned
    scale = float(np.sqrt((q * q).sum() / len(q)))
    if scale < 1e-12:
        return None
    q = q / scale
    A = np.column_stack([q, np.ones(len(q))])
    AtA = A.T @ A
    ev = np.linalg.eigvalsh(AtA[:2, :2])
    if ev[0] < 1e-10 * ev[1]:  # collinear: a circle of infinite radius
        return None
    # Kåsa: x² + y² + D x + E y + F = 0, linear in (D, E, F)
    sol = np.linalg.solve(AtA, A.T @ -(q * q).sum(axis=1))
    c = -0.5 * sol[:2]
    r2 = c @ c - sol[2]
    if not np.isfinite(r2) or r2 <= 0:
        return None
    r = float(np.sqrt(r2))
    for _ in range(refine_iterations):  # Gauss-Newton on |q - c| - r, via the 3x3 normal equations
        diff = q - c
        dist = np.sqrt((diff * diff).sum(axis=1))
        if dist.min() < 1e-12:
            break
        J = np.empty((len(q), 3))
        J[:, :2] = -diff / dist[:, None]
        J[:, 2] = -1.0
        try:
            step = np.linalg.solve(J.T @ J, -(J.T @ (dist - r)))
        except np.linalg.LinAlgError:
            break
        c = c + step[:2]
        r += float(step[2])
        if abs(step).max() < 1e-9:
            break
    if not (np.all(np.isfinite(c)) and np.isfinite(r)) or r <= 0 or r > 1e3:
        return None
    d = np.sqrt(((q - c) ** 2).sum(axis=1)) - r
    return CircleFit(center=c * scale + offset, radius=r * scale, rms=float(np.sqrt(np.mean(d * d))) * scale,
                     n=len(p))


def fit_circles_batched(points: np.ndarray, labels: np.ndarray, n_groups: int, refine_iterations: int = 3
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fit of :func:`fit_circle_2d` for many point groups at once (the centre estimate fits a dozen
    slices per plan; one vectorised pass over all of them costs about what one fit does).

    ``points`` (N, 2), ``labels`` (N,) group ids in [0, n_groups). Returns (centres (G, 2), radii (G,),
    ok (G,)); ``ok`` is False for groups with fewer than 3 points or collinear points.
    """
    G = n_groups
    count = np.bincount(labels, minlength=G).astype(float)
    safe = np.maximum(count, 1.0)
    offset = np.column_stack([np.bincount(labels, points[:, k], G) for k in range(2)]) / safe[:, None]
    q = points - offset[labels]
    scale = np.sqrt(np.bincount(labels, (q * q).sum(axis=1), G) / safe)
    ok = (count >= 3) & (scale > 1e-12)
    q = q / np.where(ok, scale, 1.0)[labels, None]

    def sums(values: np.ndarray) -> np.ndarray:
        return np.bincount(labels, values, G)

    x, y = q[:, 0], q[:, 1]
    w = x * x + y * y
    AtA = np.empty((G, 3, 3))
    AtA[:, 0, 0], AtA[:, 1, 1], AtA[:, 2, 2] = sums(x * x), sums(y * y), count
    AtA[:, 0, 1] = AtA[:, 1, 0] = sums(x * y)
    AtA[:, 0, 2] = AtA[:, 2, 0] = sums(x)
    AtA[:, 1, 2] = AtA[:, 2, 1] = sums(y)
    Atb = -np.column_stack([sums(x * w), sums(y * w), sums(w)])
    ev = np.linalg.eigvalsh(AtA[:, :2, :2])
    ok &= ev[:, 0] > 1e-10 * np.maximum(ev[:, 1], 1e-300)
    AtA[~ok] = np.eye(3)
    sol = np.linalg.solve(AtA, Atb[:, :, None])[:, :, 0]
    c = -0.5 * sol[:, :2]
    r2 = (c * c).sum(axis=1) - sol[:, 2]
    ok &= np.isfinite(r2) & (r2 > 0)
    r = np.sqrt(np.where(ok, r2, 1.0))
    for _ in range(refine_iterations):
        diff = q - c[labels]
        dist = np.maximum(np.sqrt((diff * diff).sum(axis=1)), 1e-12)
        jx, jy = -diff[:, 0] / dist, -diff[:, 1] / dist
        res = dist - r[labels]
        JtJ = np.empty((G, 3, 3))
        JtJ[:, 0, 0], JtJ[:, 1, 1], JtJ[:, 2, 2] = sums(jx * jx), sums(jy * jy), count
        JtJ[:, 0, 1] = JtJ[:, 1, 0] = sums(jx * jy)
        JtJ[:, 0, 2] = JtJ[:, 2, 0] = -sums(jx)
        JtJ[:, 1, 2] = JtJ[:, 2, 1] = -sums(jy)
        Jtr = np.column_stack([sums(jx * res), sums(jy * res), -sums(res)])
        JtJ[~ok] = np.eye(3)
        det = np.linalg.det(JtJ)
        good = ok & (np.abs(det) > 1e-18)
        JtJ[~good] = np.eye(3)
        step = -np.linalg.solve(JtJ, Jtr[:, :, None])[:, :, 0]
        step[~good] = 0.0
        c = c + step[:, :2]
        r = r + step[:, 2]
    ok &= np.all(np.isfinite(c), axis=1) & np.isfinite(r) & (r > 0) & (r < 1e3)
    return c * scale[:, None] + offset, r * scale, ok


def estimate_object_center(local_points: np.ndarray, extents: np.ndarray, slice_thickness: float,
                           n_slices: int, min_points: int, rng: np.random.Generator,
                           max_points_per_slice: int = 200, end_margin: float = 0.1
                           ) -> tuple[np.ndarray, int]:
    """Mean of circle centres fitted to random yz-slices of an axis-aligned cloud.

    ``local_points`` are in the object's box frame (x = main axis, centred on the box); ``extents`` the
    box's full side lengths. Slices avoid the ``end_margin`` fraction at each end of the main axis,
    where a lid or a cap puts points inside the circle. Only the slices' (y, z) centres are averaged;
    x is the box middle. A slice's circle is kept only when its radius is plausible (at most the box's
    yz diagonal): a near-flat slice fits a huge circle far away. Returns (centre in the box frame,
    number of slices used); with no usable slice, the box centre (0, 0, 0) and 0.
    """
    half_x = 0.5 * float(extents[0]) * (1.0 - 2.0 * end_margin)
    max_radius = float(np.hypot(extents[1], extents[2]))
    xs = local_points[:, 0]
    positions = rng.uniform(-half_x + 0.5 * slice_thickness, half_x - 0.5 * slice_thickness,
                            size=n_slices) if half_x > slice_thickness else np.zeros(1)
    groups = []
    for x0 in positions:  # a mask per slice is cheaper than sorting the cloud once
        idx = np.flatnonzero(np.abs(xs - x0) <= 0.5 * slice_thickness)
        if len(idx) >= min_points:
            groups.append(idx[:: max(1, len(idx) // max_points_per_slice)])
    if not groups:
        return np.zeros(3), 0
    labels = np.repeat(np.arange(len(groups)), [len(g) for g in groups])
    centres, radii, ok = fit_circles_batched(local_points[np.concatenate(groups), 1:], labels, len(groups))
    ok &= radii <= max_radius
    if not np.any(ok):
        return np.zeros(3), 0
    yz = centres[ok].mean(axis=0)
    # Along the main axis the slices' random positions carry no information: take the box middle.
    return np.array([0.0, yz[0], yz[1]]), int(ok.sum())
