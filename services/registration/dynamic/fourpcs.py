"""Super4PCS-style global registration: 4-points congruent sets (Aiger et al. 2008; Mellado et al. 2014).

The paper (II-C-2) aligns each neighbouring pair of views with "fast Super 4PCS" at 8 mm voxels, run with
overlaps 0.9, 0.85 and 0.8. No Python package offers it, so this is our own implementation of the method:

1. Sample ``sample_size`` points of each cloud (the source sample gives bases, the target sample the
   candidate matches) and index every target pair by its length once (a KD-tree
   ``sparse_distance_matrix`` up to the largest base length, sorted), so the pairs of any length
   d +- delta come out of a binary search - the role Super4PCS's rasterised sphere plays, at O(k) per query.
2. Per trial, a *wide coplanar base* from the source: the largest-area triangle whose sides fit in
   ``overlap`` x the source diameter, plus a fourth point within ``delta`` of its plane such that the two
   segments (b0, b1) and (b2, b3) cross; their affine invariants r1, r2 follow.
3. Congruent sets in the target (``fourpcs_kernels.match_congruent``, numba): for pairs of length d1
   (resp. d2) the points q_i + r1 (q_j - q_i) (resp. r2) are bucketed in a delta grid and couples whose
   points coincide within delta are tested in place: Super4PCS's angle filter (the segments make the
   base's angle) and the four other base distances, so only rigidly congruent sets come out (at most
   ``max_congruent_per_base``, a random subset). With normals, pairs whose normal-normal and
   normal-segment angles differ from the base's are dropped first (the Super4PCS normal filter; the angles
   are precomputed per pair in the index), which cuts the candidates by an order of magnitude.
4. Each congruent set gives a rigid transform (batched Kabsch); sets that do not fit the base within
   ``delta`` RMS are dropped. Verification is staged: every candidate is scored on a few dozen source
   points through a distance-transform grid of the target (a table lookup), and only the best few on the
   verify sample with a KD-tree over the whole target. Candidates are ranked by the weighted LCP,
   mean(max(0, 1 - d^2 / delta^2)); the plain LCP (fraction within delta, Super4PCS's measure) is
   reported too but saturates near 1 for many slightly different poses of a small object.
5. Stop at ``max_time_s``, after ``max_bases`` bases (by default the count that makes a base drawn
   entirely from the overlap likely: log(0.01) / log(1 - overlap^4), x4 for sampling losses), as soon
   as the LCP reaches ``terminate_lcp``, or - our early exit - once ``stop_after_confirmations`` further
   bases have independently found the best pose again (within delta and 3 degrees): a wrong pose is
   rarely found twice from different bases, a right one is.

The numba kernel is compiled once and cached on disk (``cache=True``); ``fourpcs_kernels.warm_up()`` pays
that at service start instead of on the first registration.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import cache
from time import perf_counter

import numpy as np
from scipy.spatial import cKDTree

from services.registration.dynamic.fourpcs_common import (
    GlobalResult,
    PointCloudInputError,
    as_optional_rows,
    as_xyz,
    check_transform,
)


@dataclass(frozen=True)
class FourPCSConfig:
    """Knobs below the public arguments; defaults suit 8 mm voxel object views of a few thousand points."""

    target_sample_factor: float = 2.0  # the target sample is this many times ``sample_size``
    verify_size: int = 600  # source points the LCP is measured on
    quick_verify_size: int = 48  # first-stage LCP subset
    full_verify_top: int = 8  # candidates per base scored on the full verify set
    max_congruent_per_base: int = 1000
    triangle_trials: int = 96
    normal_tolerance_deg: float = 20.0
    min_angle_tolerance_deg: float = 4.0
    max_kabsch_rms_factor: float = 1.0  # congruent sets fitting the base worse than this x delta are dropped
    other_distance_factor: float = 2.0  # tolerance on the 4 non-segment base distances, x delta
    stop_after_confirmations: int = 2  # stop once this many further bases found the best pose again (0: never)
    confirm_angle_deg: float = 3.0


def register_4pcs(source_xyz: np.ndarray, target_xyz: np.ndarray, *, overlap: float = 0.8,
                  delta: float = 0.008, max_time_s: float = 2.0, seed: int = 0, sample_size: int = 200,
                  source_normals: np.ndarray | None = None, target_normals: np.ndarray | None = None,
                  max_bases: int | None = None, terminate_lcp: float | None = None,
                  config: FourPCSConfig | None = None) -> GlobalResult:
    """Estimate the rigid ``T`` with ``target ~ T @ source`` from scratch (no initial guess needed).

    ``overlap`` (0..1] is the expected fraction of the source seen in the target; ``delta`` (m) the
    registration accuracy expected from the data (the voxel size is a good value). Normals (optional, any
    orientation) enable the normal filter. The result's ``lcp_score`` is measured on a source sample of up
    to ``config.verify_size`` points; ``T`` is the identity with ``lcp_score = 0`` if no base found any
    congruent set.
    """
    return register_4pcs_overlaps(source_xyz, target_xyz, overlaps=(overlap,), delta=delta,
                                  max_time_s=max_time_s, seed=seed, sample_size=sample_size,
                                  source_normals=source_normals, target_normals=target_normals,
                                  max_bases=max_bases, terminate_lcp=terminate_lcp, config=config)[0]


def register_4pcs_overlaps(source_xyz: np.ndarray, target_xyz: np.ndarray, *,
                           overlaps: Sequence[float] = (0.9, 0.85, 0.8), delta: float = 0.008,
                           max_time_s: float = 2.0, seed: int = 0, sample_size: int = 200,
                           source_normals: np.ndarray | None = None, target_normals: np.ndarray | None = None,
                           max_bases: int | None = None, terminate_lcp: float | None = None,
                           skip_after_confirmed: bool = False,
                           config: FourPCSConfig | None = None) -> list[GlobalResult]:
    """4PCS once per overlap value (the paper's 0.9, 0.85, 0.8), sharing samples, pair index and grids.

    One result per overlap that ran, in order; ``max_time_s`` is per overlap. The paper runs every overlap
    and keeps the best fitness; with ``skip_after_confirmed`` the remaining overlaps are skipped once a run
    ends with its pose confirmed by ``config.stop_after_confirmations`` further bases (the same pose would
    very likely be found again), which saves most of the time on easy pairs.
    """
    cfg = config or FourPCSConfig()
    overlaps = [float(o) for o in overlaps]
    if not overlaps or not all(0.0 < o <= 1.0 for o in overlaps):
        raise PointCloudInputError(f"overlaps must be a non-empty list of values in (0, 1], got {overlaps}",
                                   code="bad_value", detail={"field": "overlap"})
    if not delta > 0.0:
        raise PointCloudInputError(f"delta must be > 0, got {delta}", code="bad_value",
                                   detail={"field": "delta"})
    _match_congruent()  # numba's import before any clock starts: it must not eat a search's max_time_s
    problem = _Problem(source_xyz, target_xyz, source_normals, target_normals, delta=delta,
                       sample_size=sample_size, max_overlap=max(overlaps), seed=seed, cfg=cfg)
    results = []
    for k, overlap in enumerate(overlaps):
        t_run = perf_counter()
        res = _search(problem, overlap, rng=np.random.default_rng([seed, k]), max_time_s=max_time_s,
                      max_bases=default_max_bases(overlap) if max_bases is None else max_bases,
                      terminate_lcp=terminate_lcp, cfg=cfg)
        setup = problem.setup_seconds if k == 0 else 0.0
        results.append(replace(res, seconds=perf_counter() - t_run + setup))
        if skip_after_confirmed and cfg.stop_after_confirmations and \
                res.extra["confirmations"] >= cfg.stop_after_confirmations:
            break
    return results


class _Problem:
    """Everything about a (source, target) pair that does not depend on the overlap value."""

    def __init__(self, source_xyz, target_xyz, source_normals, target_normals, *, delta: float,
                 sample_size: int, max_overlap: float, seed: int, cfg: FourPCSConfig):
        t0 = perf_counter()
        src = as_xyz(source_xyz, "source_xyz", min_points=4)
        tgt = as_xyz(target_xyz, "target_xyz", min_points=4)
        src_n = _unit_rows(as_optional_rows(source_normals, src.shape[0], "source_normals"))
        tgt_n = _unit_rows(as_optional_rows(target_normals, tgt.shape[0], "target_normals"))
        self.use_normals = src_n is not None and tgt_n is not None
        rng = np.random.default_rng(seed)
        s_idx = _sample(src.shape[0], sample_size, rng)
        t_idx = _sample(tgt.shape[0], int(round(sample_size * cfg.target_sample_factor)), rng)
        self.S, self.Q = src[s_idx], tgt[t_idx]
        self.Sn = src_n[s_idx] if self.use_normals else None
        Qn = tgt_n[t_idx] if self.use_normals else None
        self.verify = src[_sample(src.shape[0], cfg.verify_size, rng)]
        self.quick = self.verify[_sample(self.verify.shape[0], cfg.quick_verify_size, rng)]
        self.target_tree = cKDTree(tgt)
        self.distance_grid = _DistanceGrid(tgt, delta)
        self.delta = float(delta)
        self.diameter = _diameter(self.S)
        self.pair_index = _PairIndex(self.Q, max_len=max_overlap * self.diameter + 2.0 * delta, normals=Qn)
        self.centre = self.S.mean(axis=0)
        self.setup_seconds = perf_counter() - t0


def _search(p: _Problem, overlap: float, *, rng: np.random.Generator, max_time_s: float, max_bases: int,
            terminate_lcp: float | None, cfg: FourPCSConfig) -> GlobalResult:
    """The 4PCS loop for one overlap value: bases, congruent sets, staged LCP, early exits."""
    t_start = perf_counter()
    delta = p.delta
    max_base = overlap * p.diameter
    best_T, best_lcp, best_score, n_bases = np.eye(4), 0.0, 0.0, 0
    confirmations = 0  # later bases that found the current best pose again
    n_congruent_total = 0
    while n_bases < max_bases and perf_counter() - t_start < max_time_s:
        n_bases += 1
        base = _select_base(p.S, rng, max_base=max_base, coplanar_tol=delta, trials=cfg.triangle_trials)
        if base is None:
            continue
        quad, r1, r2 = base
        B = p.S[quad]
        BN = p.Sn[quad] if p.use_normals else None
        quads = _congruent_sets(p.Q, p.pair_index, B, BN, r1, r2, delta, cfg, rng)
        if quads.shape[0] == 0:
            continue
        n_congruent_total += int(quads.shape[0])
        R, t, rms = _kabsch_batch(B, p.Q[quads])
        ok = rms <= cfg.max_kabsch_rms_factor * delta
        if not np.any(ok):
            continue
        R, t = R[ok], t[ok]
        quick_scores = p.distance_grid.weighted_lcp(p.quick, R, t)
        order = np.argsort(-quick_scores, kind="stable")[: cfg.full_verify_top]
        order = order[quick_scores[order] >= 0.8 * best_score]  # staged early rejection
        if order.size == 0:
            continue
        hard, soft = lcp_batch(p.verify, R[order], t[order], p.target_tree, delta)
        k = int(np.argmax(soft))
        T_k = np.eye(4)
        T_k[:3, :3], T_k[:3, 3] = R[order[k]], t[order[k]]
        same_pose = best_score > 0 and _same_pose(T_k, best_T, p.centre, delta, cfg.confirm_angle_deg)
        if soft[k] > best_score:
            best_score, best_lcp, best_T = float(soft[k]), float(hard[k]), T_k
        confirmations = confirmations + 1 if same_pose else (0 if best_T is T_k else confirmations)
        if terminate_lcp is not None and best_lcp >= terminate_lcp:
            break
        if cfg.stop_after_confirmations and confirmations >= cfg.stop_after_confirmations:
            break
    return GlobalResult(T=best_T, lcp_score=best_lcp, score=best_score, n_bases_tried=n_bases,
                        seconds=perf_counter() - t_start, method="4pcs", overlap=float(overlap),
                        extra={"n_congruent": n_congruent_total, "diameter": p.diameter,
                               "used_normals": p.use_normals, "confirmations": confirmations})


def _same_pose(Ta: np.ndarray, Tb: np.ndarray, centre: np.ndarray, delta: float, angle_deg: float) -> bool:
    """Two transforms agree: the source centre lands within ``delta`` and rotations within ``angle_deg``."""
    moved = np.linalg.norm((Ta[:3, :3] - Tb[:3, :3]) @ centre + Ta[:3, 3] - Tb[:3, 3])
    c = (np.trace(Ta[:3, :3].T @ Tb[:3, :3]) - 1.0) / 2.0
    return bool(moved <= delta and math.degrees(math.acos(max(-1.0, min(1.0, c)))) <= angle_deg)


@cache
def _match_congruent() -> Callable[..., np.ndarray]:
    """The numba kernel of the congruent-set search, imported on first need: numba costs ~0.6 CPU-s to import
    and most reconstructions never run a global search."""
    from services.registration.dynamic.fourpcs_kernels import match_congruent

    return match_congruent


def default_max_bases(overlap: float, success: float = 0.99, factor: float = 4.0) -> int:
    """Bases to draw so that one lies entirely in the overlap with probability ``success`` (times ``factor``).

    A base is 4 points, each in the overlap with probability ~``overlap``; 4PCS's own trial count.
    """
    p = max(min(overlap, 0.999), 1e-3) ** 4
    return max(8, int(math.ceil(factor * math.log(1.0 - success) / math.log(1.0 - p))))


def score_alignment(source_xyz: np.ndarray, target_xyz: np.ndarray | cKDTree, T: np.ndarray,
                    delta: float) -> tuple[float, float]:
    """(LCP, weighted LCP) of the source after ``T`` against the target (points or their KD-tree) at ``delta``.

    LCP is the fraction of source points within ``delta`` of the target; the weighted one,
    mean(max(0, 1 - d^2 / delta^2)), is the score candidates are ranked by.
    """
    src = as_xyz(source_xyz, "source_xyz")
    tree = target_xyz if isinstance(target_xyz, cKDTree) else cKDTree(as_xyz(target_xyz, "target_xyz"))
    T = check_transform(T)
    hard, soft = lcp_batch(src, T[None, :3, :3], T[None, :3, 3], tree, delta)
    return float(hard[0]), float(soft[0])


class _DistanceGrid:
    """Approximate distance-to-target field on a grid of cell delta/2 (Euclidean distance transform).

    The first verification stage scores thousands of candidate transforms on a few dozen points each;
    a table lookup is ~50x cheaper than KD-tree queries and its error (about one cell) is harmless there:
    survivors are re-scored exactly with the KD-tree.
    """

    def __init__(self, target: np.ndarray, delta: float):
        self.delta = float(delta)
        self.cell = 0.5 * self.delta
        self.origin = target.min(axis=0) - 2.0 * self.delta
        shape = np.ceil((target.max(axis=0) + 2.0 * self.delta - self.origin) / self.cell).astype(int) + 1
        occupied = np.zeros(tuple(shape), dtype=bool)
        idx = np.floor((target - self.origin) / self.cell).astype(int)
        occupied[idx[:, 0], idx[:, 1], idx[:, 2]] = True
        from scipy.ndimage import distance_transform_edt  # here, not at import: only the global search scores

        dist = distance_transform_edt(~occupied, sampling=self.cell)
        self.weight = np.clip(1.0 - (dist / self.delta) ** 2, 0.0, None).astype(np.float32).ravel()
        self.shape = shape

    def weighted_lcp(self, P: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Approximate weighted LCP of points ``P`` under each of the M transforms (R, t)."""
        moved = np.matmul(P, np.transpose(R, (0, 2, 1))) + t[:, None, :]
        idx = np.floor((moved - self.origin) / self.cell).astype(np.int64)
        inside = np.all((idx >= 0) & (idx < self.shape), axis=2)
        flat = np.ravel_multi_index(tuple(np.clip(idx, 0, self.shape - 1).transpose(2, 0, 1)), tuple(self.shape))
        return np.where(inside, self.weight[flat], 0.0).mean(axis=1)


class _PairIndex:
    """All unordered target pairs up to ``max_len``, sorted by length for O(log n + k) range queries.

    With normals, each pair also carries its three rotation-invariant angles (normal-normal, normal_i-segment,
    normal_j-segment; absolute cosines, so normal orientation does not matter), computed once here so the
    per-base normal filter is a comparison on a slice.
    """

    def __init__(self, Q: np.ndarray, max_len: float, normals: np.ndarray | None = None):
        tree = cKDTree(Q)
        sdm = tree.sparse_distance_matrix(tree, max_len, output_type="ndarray")
        upper = sdm["i"] < sdm["j"]
        order = np.argsort(sdm["v"][upper], kind="stable")
        self.i = sdm["i"][upper][order].astype(np.int64)
        self.j = sdm["j"][upper][order].astype(np.int64)
        self.d = sdm["v"][upper][order]
        self.angles = None if normals is None else _pair_angles(Q[self.i], Q[self.j], normals[self.i],
                                                                normals[self.j])

    def ordered_pairs(self, length: float, tol: float, base_angles: np.ndarray | None = None,
                      angle_tol: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Both orders (i, j) and (j, i) of every pair whose length is within ``tol`` of ``length``.

        With ``base_angles`` (the base pair's three angles, radians) only pairs whose angles match within
        ``angle_tol`` are returned; the reversed order swaps the two normal-segment angles.
        """
        lo, hi = np.searchsorted(self.d, [length - tol, length + tol])
        i, j = self.i[lo:hi], self.j[lo:hi]
        if base_angles is None or self.angles is None:
            return np.concatenate([i, j]), np.concatenate([j, i])
        ang = self.angles[lo:hi]
        common = np.abs(ang[:, 0] - base_angles[0]) <= angle_tol
        fwd = common & (np.abs(ang[:, 1] - base_angles[1]) <= angle_tol) & \
            (np.abs(ang[:, 2] - base_angles[2]) <= angle_tol)
        rev = common & (np.abs(ang[:, 2] - base_angles[1]) <= angle_tol) & \
            (np.abs(ang[:, 1] - base_angles[2]) <= angle_tol)
        return np.concatenate([i[fwd], j[rev]]), np.concatenate([j[fwd], i[rev]])


def _pair_angles(pi: np.ndarray, pj: np.ndarray, ni: np.ndarray, nj: np.ndarray) -> np.ndarray:
    """(K, 3) angles (rad) of |n_i.n_j|, |n_i.seg|, |n_j.seg| for segments pi -> pj."""
    seg = pj - pi
    seg = seg / np.maximum(np.linalg.norm(seg, axis=-1, keepdims=True), 1e-12)
    cos = np.abs(np.stack([np.sum(ni * nj, axis=-1), np.sum(ni * seg, axis=-1), np.sum(nj * seg, axis=-1)],
                          axis=-1))
    return np.arccos(np.clip(cos, 0.0, 1.0))


def _congruent_sets(Q: np.ndarray, pairs: _PairIndex, B: np.ndarray,
                    BN: np.ndarray | None, r1: float, r2: float, delta: float, cfg: FourPCSConfig,
                    rng: np.random.Generator) -> np.ndarray:
    """(M, 4) target indices of the 4-point sets congruent with base ``B`` (rows b0, b1, b2, b3)."""
    u_base, v_base = B[1] - B[0], B[3] - B[2]
    d1, d2 = float(np.linalg.norm(u_base)), float(np.linalg.norm(v_base))
    angle_tol = math.radians(cfg.normal_tolerance_deg)
    a1 = a2 = None
    if BN is not None:
        a1 = _pair_angles(B[0], B[1], BN[0], BN[1])
        a2 = _pair_angles(B[2], B[3], BN[2], BN[3])
    i1, j1 = pairs.ordered_pairs(d1, delta, a1, angle_tol)
    i2, j2 = pairs.ordered_pairs(d2, delta, a2, angle_tol)
    if i1.size == 0 or i2.size == 0:
        return np.empty((0, 4), dtype=np.int64)
    perm = rng.permutation(i1.size)  # the kernel stops at max_out: make that a random subset
    i1, j1 = i1[perm], j1[perm]
    e1 = Q[i1] + r1 * (Q[j1] - Q[i1])
    e2 = Q[i2] + r2 * (Q[j2] - Q[i2])
    theta = math.acos(max(-1.0, min(1.0, float(u_base @ v_base / (d1 * d2)))))
    tol = max(math.radians(cfg.min_angle_tolerance_deg), 2.0 * delta / min(d1, d2))
    cos_lo, cos_hi = math.cos(min(math.pi, theta + tol)), math.cos(max(0.0, theta - tol))
    base_d = np.array([np.linalg.norm(B[0] - B[2]), np.linalg.norm(B[0] - B[3]),
                       np.linalg.norm(B[1] - B[2]), np.linalg.norm(B[1] - B[3])])
    return _match_congruent()(Q, i1, j1, e1, i2, j2, e2, float(delta), cos_lo, cos_hi, base_d,
                              cfg.other_distance_factor * delta, cfg.max_congruent_per_base)


def _select_base(S: np.ndarray, rng: np.random.Generator, *, max_base: float, coplanar_tol: float,
                 trials: int) -> tuple[np.ndarray, float, float] | None:
    """A wide, coplanar 4-point base from the source sample: (indices b0..b3, r1, r2), or None.

    (b0, b1) and (b2, b3) are the two crossing segments; r1, r2 locate their intersection on each.
    """
    n = S.shape[0]
    tri = rng.integers(0, n, size=(trials, 3))
    a, b, c = S[tri[:, 0]], S[tri[:, 1]], S[tri[:, 2]]
    sides = np.column_stack([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - a, axis=1),
                             np.linalg.norm(c - b, axis=1)])
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    valid = (sides.max(axis=1) <= max_base) & (sides.min(axis=1) > 2.0 * coplanar_tol)
    valid &= area > (2.0 * coplanar_tol) ** 2  # not (nearly) collinear: the base plane must be defined
    if not np.any(valid):
        return None
    k = int(np.argmax(np.where(valid, area, -1.0)))
    ia, ib, ic = (int(v) for v in tri[k])
    pa, pb, pc = S[ia], S[ib], S[ic]
    normal = np.cross(pb - pa, pc - pa)
    normal /= np.linalg.norm(normal)
    near = np.flatnonzero(np.abs((S - pa) @ normal) <= coplanar_tol)
    near = near[(near != ia) & (near != ib) & (near != ic)]
    if near.size == 0:
        return None
    X = S[near]
    spread = np.min(np.column_stack([np.linalg.norm(X - p, axis=1) for p in (pa, pb, pc)]), axis=1)
    best: tuple[float, np.ndarray, float, float] | None = None
    # the three ways to split {a, b, c, x} into segments (s0, s1) and (s2, x); keep ones that cross
    for s0, s1, s2 in ((ia, ib, ic), (ia, ic, ib), (ib, ic, ia)):
        t, s = _line_params(S[s0], S[s1], S[s2], X)
        ok = (t >= 0.1) & (t <= 0.9) & (s >= 0.1) & (s <= 0.9) & (spread > 2.0 * coplanar_tol)
        ok &= np.linalg.norm(X - S[s2], axis=1) <= max_base
        if not np.any(ok):
            continue
        m = int(np.argmax(np.where(ok, spread, -1.0)))
        if best is None or spread[m] > best[0]:
            best = (float(spread[m]), np.array([s0, s1, s2, int(near[m])]), float(t[m]), float(s[m]))
    if best is None:
        return None
    return best[1], best[2], best[3]


def _line_params(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray,
                 X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parameters (t, s) of the closest points of lines p0 + t (p1 - p0) and p2 + s (x - p2), per x in X."""
    u = p1 - p0
    v = X - p2
    w = p0 - p2
    a = u @ u
    b = v @ u
    c = np.einsum("ij,ij->i", v, v)
    d = u @ w
    e = v @ w
    den = a * c - b * b
    den = np.where(np.abs(den) < 1e-18, np.nan, den)
    t = (b * e - c * d) / den
    s = (a * e - b * d) / den
    return np.nan_to_num(t, nan=-1.0), np.nan_to_num(s, nan=-1.0)


def _kabsch_batch(B: np.ndarray, Qs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares rigid fits of base ``B`` (4, 3) onto each ``Qs[m]`` (M, 4, 3): (R, t, rms)."""
    cb = B.mean(axis=0)
    cq = Qs.mean(axis=1)
    H = np.einsum("ki,mkj->mij", B - cb, Qs - cq[:, None, :])
    U, _, Vt = np.linalg.svd(H)
    V = np.transpose(Vt, (0, 2, 1))
    det = np.sign(np.linalg.det(V @ np.transpose(U, (0, 2, 1))))
    D = np.zeros_like(H)
    D[:, 0, 0] = 1.0
    D[:, 1, 1] = 1.0
    D[:, 2, 2] = np.where(det == 0, 1.0, det)
    R = V @ D @ np.transpose(U, (0, 2, 1))
    t = cq - np.einsum("mij,j->mi", R, cb)
    moved = np.einsum("mij,kj->mki", R, B) + t[:, None, :]
    rms = np.sqrt(np.mean(np.sum((moved - Qs) ** 2, axis=2), axis=1))
    return R, t, rms


def lcp_batch(P: np.ndarray, R: np.ndarray, t: np.ndarray, tree: cKDTree,
               delta: float) -> tuple[np.ndarray, np.ndarray]:
    """(LCP, weighted LCP) of points ``P`` under each of the M transforms.

    LCP is the fraction of points within ``delta`` of the target. On small objects with delta ~ voxel it
    saturates near 1 for many slightly different poses, so candidates are ranked by the weighted LCP,
    mean(max(0, 1 - d^2 / delta^2)), which also rewards being close, not just within delta.
    """
    moved = np.matmul(P, np.transpose(R, (0, 2, 1))) + t[:, None, :]
    dist, _ = tree.query(moved.reshape(-1, 3), k=1, distance_upper_bound=delta)
    dist = dist.reshape(R.shape[0], P.shape[0])
    inside = np.isfinite(dist)
    weight = np.where(inside, 1.0 - (np.where(inside, dist, 0.0) / delta) ** 2, 0.0)
    return inside.mean(axis=1), weight.mean(axis=1)


def _sample(n: int, k: int, rng: np.random.Generator) -> np.ndarray:
    return np.arange(n) if k >= n else np.sort(rng.choice(n, size=k, replace=False))


def _diameter(P: np.ndarray) -> float:
    """Largest pairwise distance (exact on up to ~1000 points; sampled beyond)."""
    X = P if P.shape[0] <= 1000 else P[:: int(math.ceil(P.shape[0] / 1000))]
    d2 = np.sum(X**2, axis=1)
    g = d2[:, None] + d2[None, :] - 2.0 * X @ X.T
    return float(np.sqrt(max(float(g.max()), 0.0)))


def _unit_rows(v: np.ndarray | None) -> np.ndarray | None:
    if v is None:
        return None
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)
