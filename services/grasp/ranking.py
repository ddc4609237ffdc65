"""GeoGrasp's ranking of contact pairs, identical to the authors' code (Zapata-Impata et al. 2019).

For every pair (i in region A, j in region B):
    d̂, ĉ  = distance to the central plane and curvature, min-max normalised within each region
    cosβ  = |cos(grasp line, main axis)|,  cosαk = |cos(grasp line, normal k)|
    r1    = 2 − d̂i − d̂j − 10·(cosβ − 0.2)
    r2    = 2 − ĉi − ĉj + 2·min(cosαi, cosαj)
    rank  = 1.5·r1 + r2
Pairs with r1 < 1 or r2 < 1, or wider than the gripper opens, are dropped; so are (our addition)
pairs whose grasp line is too steep for the approach and pairs that are not antipodal. The whole pair table is
computed at once with numpy broadcasting.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.grasp.candidates import CandidateRegion
from services.grasp.config import GraspPlannerConfig

PAIR_REASONS = ("too_wide", "grasp_line_not_horizontal", "not_antipodal", "rank_below_threshold")


def minmax_normalise(x: np.ndarray) -> np.ndarray:
    """(x − min)/(max − min); all zeros when the values are equal (GeoGrasp would divide by zero)."""
    if len(x) == 0:
        return x
    lo, hi = float(x.min()), float(x.max())
    if hi - lo < 1e-12:
        return np.zeros_like(x)
    return (x - lo) / (hi - lo)


@dataclass(frozen=True)
class RankedPair:
    """One ranked contact pair; ``metrics`` holds every term of the ranking."""

    i: int  # cloud index of contact 1
    j: int  # cloud index of contact 2
    rank: float
    metrics: dict[str, float]
    n_i: np.ndarray  # the normals the ranking used
    n_j: np.ndarray


@dataclass(frozen=True)
class PairRanking:
    """The best valid pairs (best first) and, per rejection reason, how many pairs and the best one."""

    best: list[RankedPair]
    rejected_counts: dict[str, int]
    rejected_best: dict[str, RankedPair]
    n_pairs: int


def _region_normals(region: CandidateRegion, normals: np.ndarray) -> np.ndarray:
    """The region's own (re-estimated) normals where it has them, else the input normals."""
    given = normals[region.indices]
    if region.normals is None:
        return given
    return np.where(np.isfinite(region.normals).all(axis=1)[:, None], region.normals, given)


def rank_region_pair(a: CandidateRegion, b: CandidateRegion, points: np.ndarray, normals: np.ndarray,
                     main_axis: np.ndarray, up: np.ndarray, cfg: GraspPlannerConfig, top_k: int
                     ) -> PairRanking:
    """Rank all pairs between regions ``a`` and ``b`` and keep the ``top_k`` best valid ones."""
    pa, pb = points[a.indices], points[b.indices]
    na, nb = _region_normals(a, normals), _region_normals(b, normals)
    line = pb[None, :, :] - pa[:, None, :]  # (A, B, 3)
    width = np.linalg.norm(line, axis=2)
    unit = line / np.maximum(width, 1e-12)[:, :, None]
    cos_beta = np.abs(unit @ main_axis)
    cos_a1 = np.abs(np.einsum("abk,ak->ab", unit, na))
    cos_a2 = np.abs(np.einsum("abk,bk->ab", unit, nb))
    d1 = minmax_normalise(a.plane_distance)[:, None]
    d2 = minmax_normalise(b.plane_distance)[None, :]
    c1 = minmax_normalise(a.curvature)[:, None]
    c2 = minmax_normalise(b.curvature)[None, :]
    r1 = 2.0 - d1 - d2 - cfg.cos_beta_gain * (cos_beta - cfg.cos_beta_offset)
    r2 = 2.0 - c1 - c2 + 2.0 * np.minimum(cos_a1, cos_a2)
    rank = cfg.w1 * r1 + cfg.w2 * r2
    sin_tilt = np.abs(unit @ up)

    g = cfg.gripper
    too_wide = (width > g.max_opening) | (width < g.min_opening) | (width < 1e-9)
    not_horizontal = ~too_wide & (sin_tilt > np.sin(np.radians(cfg.max_grasp_line_tilt_deg)))
    not_antipodal = ~too_wide & ~not_horizontal & (
        np.minimum(cos_a1, cos_a2) < np.cos(np.radians(cfg.max_contact_angle_deg)))
    low_rank = ~(too_wide | not_horizontal | not_antipodal) & ((r1 < cfg.r1_min) | (r2 < cfg.r2_min))
    valid = ~(too_wide | not_horizontal | not_antipodal | low_rank)

    def pair(flat: int) -> RankedPair:
        ia, ib = np.unravel_index(flat, rank.shape)
        m = {
            "width": float(width[ia, ib]),
            "d1": float(a.plane_distance[ia]), "d2": float(b.plane_distance[ib]),
            "d1_norm": float(d1[ia, 0]), "d2_norm": float(d2[0, ib]),
            "c1": float(a.curvature[ia]), "c2": float(b.curvature[ib]),
            "c1_norm": float(c1[ia, 0]), "c2_norm": float(c2[0, ib]),
            "cos_beta": float(cos_beta[ia, ib]),
            "cos_alpha1": float(cos_a1[ia, ib]), "cos_alpha2": float(cos_a2[ia, ib]),
            "r1": float(r1[ia, ib]), "r2": float(r2[ia, ib]), "rank": float(rank[ia, ib]),
        }
        return RankedPair(int(a.indices[ia]), int(b.indices[ib]), m["rank"], m, na[ia], nb[ib])

    def best_of(mask: np.ndarray, k: int) -> list[RankedPair]:
        flat = np.flatnonzero(mask)
        if len(flat) == 0:
            return []
        scores = rank.ravel()[flat]
        k = min(k, len(flat))
        top = flat[np.argpartition(-scores, k - 1)[:k]] if k < len(flat) else flat
        top = top[np.argsort(-rank.ravel()[top], kind="stable")]
        return [pair(int(f)) for f in top]

    counts, examples = {}, {}
    for reason, mask in zip(PAIR_REASONS, (too_wide, not_horizontal, not_antipodal, low_rank), strict=True):
        n = int(np.count_nonzero(mask))
        if n:
            counts[reason] = n
            examples[reason] = best_of(mask, 1)[0]
    return PairRanking(best_of(valid, top_k), counts, examples, int(rank.size))
