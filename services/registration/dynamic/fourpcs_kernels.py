"""numba kernels of the 4PCS congruent-set search (compiled once, cached on disk with ``cache=True``).

Matching the intermediate points of two pair sets is the hot loop of 4PCS: on 8 mm object views there are
10^4 - 10^5 pairs per side, and matching them with array operations materialises millions of candidate
couples only to throw most away. Here the second set is bucketed in a uniform grid of cell ``radius``
(Super4PCS indexes them in a grid too) and every couple is tested in place - intermediate points within
``radius``, the base's angle between the segments, and the four remaining base distances - so only
rigidly congruent 4-point sets ever leave the kernel.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _grid_keys(cells: np.ndarray, lo: np.ndarray, dims: np.ndarray) -> np.ndarray:
    n = cells.shape[0]
    keys = np.empty(n, dtype=np.int64)
    for k in range(n):
        keys[k] = ((cells[k, 0] - lo[0]) * dims[1] + (cells[k, 1] - lo[1])) * dims[2] + (cells[k, 2] - lo[2])
    return keys


@njit(cache=True)
def match_congruent(Q: np.ndarray, i1: np.ndarray, j1: np.ndarray, e1: np.ndarray, i2: np.ndarray,
                    j2: np.ndarray, e2: np.ndarray, radius: float, cos_lo: float, cos_hi: float,
                    base_d: np.ndarray, dist_tol: float, max_out: int) -> np.ndarray:
    """(M, 4) target indices (i1, j1, i2, j2) of the 4-point sets congruent with the base.

    ``base_d`` holds the base distances |b0-b2|, |b0-b3|, |b1-b2|, |b1-b3|; the angle between the two
    segments must have its cosine in [cos_lo, cos_hi]. At most ``max_out`` sets are returned (first found).
    """
    out = np.empty((max_out, 4), dtype=np.int64)
    n_out = 0
    if e1.shape[0] == 0 or e2.shape[0] == 0:
        return out[:0]
    inv = 1.0 / radius
    cells2 = np.floor(e2 * inv).astype(np.int64)
    lo = np.empty(3, dtype=np.int64)
    hi = np.empty(3, dtype=np.int64)
    for a in range(3):
        lo[a] = cells2[:, a].min() - 1
        hi[a] = cells2[:, a].max() + 1
    dims = hi - lo + 1
    keys = _grid_keys(cells2, lo, dims)
    order = np.argsort(keys)
    sorted_keys = keys[order]
    r2 = radius * radius
    for a in range(e1.shape[0]):
        cx = np.int64(np.floor(e1[a, 0] * inv))
        cy = np.int64(np.floor(e1[a, 1] * inv))
        cz = np.int64(np.floor(e1[a, 2] * inv))
        if cx < lo[0] or cx > hi[0] or cy < lo[1] or cy > hi[1] or cz < lo[2] or cz > hi[2]:
            continue
        p0 = i1[a]
        p1 = j1[a]
        ux = Q[p1, 0] - Q[p0, 0]
        uy = Q[p1, 1] - Q[p0, 1]
        uz = Q[p1, 2] - Q[p0, 2]
        un = np.sqrt(ux * ux + uy * uy + uz * uz)
        for dx in range(-1, 2):
            x = cx + dx
            if x < lo[0] or x > hi[0]:
                continue
            for dy in range(-1, 2):
                y = cy + dy
                if y < lo[1] or y > hi[1]:
                    continue
                for dz in range(-1, 2):
                    z = cz + dz
                    if z < lo[2] or z > hi[2]:
                        continue
                    key = ((x - lo[0]) * dims[1] + (y - lo[1])) * dims[2] + (z - lo[2])
                    s = np.searchsorted(sorted_keys, key)
                    while s < sorted_keys.shape[0] and sorted_keys[s] == key:
                        b = order[s]
                        s += 1
                        ddx = e1[a, 0] - e2[b, 0]
                        ddy = e1[a, 1] - e2[b, 1]
                        ddz = e1[a, 2] - e2[b, 2]
                        if ddx * ddx + ddy * ddy + ddz * ddz > r2:
                            continue
                        q2 = i2[b]
                        q3 = j2[b]
                        if q2 == p0 or q2 == p1 or q3 == p0 or q3 == p1:  # noqa: SIM109 (numba)
                            continue
                        vx = Q[q3, 0] - Q[q2, 0]
                        vy = Q[q3, 1] - Q[q2, 1]
                        vz = Q[q3, 2] - Q[q2, 2]
                        vn = np.sqrt(vx * vx + vy * vy + vz * vz)
                        c = (ux * vx + uy * vy + uz * vz) / (un * vn + 1e-12)
                        if c < cos_lo or c > cos_hi:
                            continue
                        ok = True
                        for m in range(4):
                            pa = p0 if m < 2 else p1
                            pb = q2 if m % 2 == 0 else q3
                            gx = Q[pa, 0] - Q[pb, 0]
                            gy = Q[pa, 1] - Q[pb, 1]
                            gz = Q[pa, 2] - Q[pb, 2]
                            if abs(np.sqrt(gx * gx + gy * gy + gz * gz) - base_d[m]) > dist_tol:
                                ok = False
                                break
                        if not ok:
                            continue
                        out[n_out, 0] = p0
                        out[n_out, 1] = p1
                        out[n_out, 2] = q2
                        out[n_out, 3] = q3
                        n_out += 1
                        if n_out == max_out:
                            return out
    return out[:n_out]


def warm_up() -> None:
    """Compile (or load from the on-disk cache) the kernels now, so the first registration is not slowed.

    A service can call this at start-up: ~10 s the first time on this machine, well under 1 s from cache.
    """
    Q = np.random.default_rng(0).uniform(size=(8, 3))
    idx = np.arange(8, dtype=np.int64)
    match_congruent(Q, idx, idx[::-1].copy(), Q, idx, idx[::-1].copy(), Q, 0.1, -1.0, 1.0,
                    np.zeros(4), 1.0, 4)
