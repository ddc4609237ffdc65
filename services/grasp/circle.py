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
    q = p - offset  # centring keeps the normal equations well conditioned
    scale = float(np.sqrt((q**2).sum(axis=1).mean()))
    if scale < 1e-12:
        return None
    q = q / scale
    sv = np.linalg.svd(q, compute_uv=False)
    if sv[-1] < 1e-6 * sv[0]:  # collinear: a circle of infinite radius
        return None
    # Kåsa: x² + y² + D x + E y + F = 0, linear in (D, E, F)
    A = np.column_stack([q, np.ones(len(q))])
    b = -(q**2).sum(axis=1)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    c = -0.5 * sol[:2]
    r2 = c @ c - sol[2]
    if not np.isfinite(r2) or r2 <= 0:
        return None
    r = float(np.sqrt(r2))
    for _ in range(refine_iterations):
        diff = q - c
        dist = np.linalg.norm(diff, axis=1)
        if np.any(dist < 1e-12):
            break
        res = dist - r
        J = np.column_stack([-diff / dist[:, None], -np.ones(len(q))])
        try:  # normal equations: a 3x3 solve is far cheaper than an SVD of the N x 3 Jacobian
            step = np.linalg.solve(J.T @ J, -(J.T @ res))
        except np.linalg.LinAlgError:
            break
        c = c + step[:2]
        r = r + float(step[2])
        if np.linalg.norm(step) < 1e-10:
            break
    if not (np.all(np.isfinite(c)) and np.isfinite(r)) or r <= 0 or r > 1e3:
        return None
    rms = float(np.sqrt(np.mean((np.linalg.norm(q - c, axis=1) - r) ** 2)))
    return CircleFit(center=c * scale + offset, radius=r * scale, rms=rms * scale, n=len(p))


def estimate_object_center(local_points: np.ndarray, extents: np.ndarray, slice_thickness: float,
                           n_slices: int, min_points: int, rng: np.random.Generator,
                           max_points_per_slice: int = 400, end_margin: float = 0.1
                           ) -> tuple[np.ndarray, int]:
    """Mean of circle centres fitted to random yz-slices of an axis-aligned cloud.

    ``local_points`` are in the object's box frame (x = main axis, centred on the box); ``extents`` the
    box's full side lengths. A slice's circle is kept only when its radius is plausible (at most the
    box's yz diagonal): a near-flat slice fits a huge circle far away. Returns (centre in the box
    frame, number of slices used); with no usable slice, the box centre (0, 0, 0) and 0.
    """
    half_x = 0.5 * float(extents[0]) * (1.0 - 2.0 * end_margin)
    max_radius = float(np.hypot(extents[1], extents[2]))
    order = np.argsort(local_points[:, 0])  # sorted once; each slice is then two binary searches
    xs = local_points[order, 0]
    positions = rng.uniform(-half_x + 0.5 * slice_thickness, half_x - 0.5 * slice_thickness,
                            size=n_slices) if half_x > slice_thickness else np.zeros(1)
    centres = []
    for x0 in positions:
        lo, hi = np.searchsorted(xs, [x0 - 0.5 * slice_thickness, x0 + 0.5 * slice_thickness])
        if hi - lo < min_points:
            continue
        sel = order[lo:hi:max(1, (hi - lo) // max_points_per_slice)]
        fit = fit_circle_2d(local_points[sel, 1:])
        if fit is None or fit.radius > max_radius:
            continue
        centres.append(fit.center)
    if not centres:
        return np.zeros(3), 0
    yz = np.mean(np.asarray(centres), axis=0)
    # Along the main axis the slices' random positions carry no information: take the box middle.
    return np.array([0.0, yz[0], yz[1]]), len(centres)
