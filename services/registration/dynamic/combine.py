"""Combining the views with the pair transforms (paper II-C-3), and loop/consistency figures.

The 12 pair transforms include the 0°–330° loop closure, so one is redundant. The paper drops the
lowest-fitness one, chains the remaining 11 from view 0, and as each view is attached it crops the
overlap of the two scans and refines once more with point-to-plane ICP.

Conventions: a pair result's ``T`` maps its source view onto its target view (pre-processed frames).
A pose ``P[k]`` maps pre-processed view k into the model frame, which is pre-processed view 0 (= view
0's ``base``), so ``P[source] = P[target] @ T``.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from common.geometry import invert, rotation_angle_deg
from services.registration.dynamic.pair import PairResult, crop_to_overlap
from services.registration.dynamic.preprocess import Prepared
from services.registration.dynamic.views import DynamicRegistrationError

reg = o3d.pipelines.registration


@dataclass(frozen=True)
class CombineConfig:
    """Settings of the combination stage (both the paper's chain and the pose graph)."""

    method: str = "pose_graph"  # "pose_graph" (beyond the paper) | "paper" (drop lowest fitness, chain)
    refine: bool = True  # the paper's crop-and-point-to-plane refinement as views are attached
    refine_voxel: float = 0.002
    refine_max_corr: float = 0.004
    crop_angle_deg: float = 4.0
    consistency_voxel: float = 0.003
    consistency_distance: float = 0.003
    # a point farther than this from its posed neighbour is outside what the two views share (the overlap), not
    # misplaced: posed agreement is judged on the points within it
    overlap_distance: float = 0.010
    # pose graph
    pg_max_correspondence: float = 0.004
    pg_edge_prune_threshold: float = 0.25
    pg_uncertain: str = "all"  # which edges the line process may prune: "all" | "loop"


@dataclass
class CombineResult:
    """Poses of every view in the model frame and what was done to get them."""

    poses: list[np.ndarray]
    method: str
    dropped_edge: int | None = None
    detail: dict = field(default_factory=dict)


def chain_poses(n_views: int, results: list[PairResult], skip: set[int] | None = None) -> list[np.ndarray]:
    """Poses from pair transforms by walking the edge graph outward from view 0 (breadth first)."""
    skip = skip or set()
    poses: list[np.ndarray | None] = [None] * n_views
    poses[0] = np.eye(4)
    queue = deque([0])
    while queue:
        k = queue.popleft()
        for r in results:
            if r.index in skip:
                continue
            if r.target_view == k and poses[r.source_view] is None:
                poses[r.source_view] = poses[k] @ r.T
                queue.append(r.source_view)
            elif r.source_view == k and poses[r.target_view] is None:
                poses[r.target_view] = poses[k] @ invert(r.T)
                queue.append(r.target_view)
    if any(p is None for p in poses):
        raise DynamicRegistrationError("pair edges do not connect every view", code="disconnected",
                                       detail={"missing": [i for i, p in enumerate(poses) if p is None]})
    return [np.asarray(p) for p in poses]


def loop_closure_error(results: list[PairResult], center: np.ndarray) -> dict:
    """How far the composition of all pair transforms around the loop is from identity.

    Returned as the rotation (deg) and the displacement of the object centre (mm): a translation at
    ``base``'s origin would mix in the lever arm of the rotation.
    """
    by_source = {r.source_view: r for r in results}
    n = len(results)
    L = np.eye(4)
    view = 0
    for _ in range(n):  # follow source -> target around the loop: 0 -> n-1 -> ... -> 1 -> 0
        r = by_source.get(view)
        if r is None:
            return {"rotation_deg": float("nan"), "translation_mm": float("nan")}
        L = r.T @ L
        view = r.target_view
    c = np.asarray(center, dtype=float)
    return {"rotation_deg": rotation_angle_deg(L[:3, :3]),
            "translation_mm": 1000.0 * float(np.linalg.norm(L[:3, :3] @ c + L[:3, 3] - c))}


def _posed(prep: Prepared, k: int, P: np.ndarray, voxel: float):
    return prep.views[k].reduced.downsampled(voxel).transformed(P)


def refine_attachment(prep: Prepared, P_new: np.ndarray, k_new: int, P_ref: np.ndarray, k_ref: int,
                      cfg: CombineConfig) -> np.ndarray:
    """Crop the overlap of the new view and its neighbour (both posed) and refine with point-to-plane."""
    s = _posed(prep, k_new, P_new, cfg.refine_voxel)
    t = _posed(prep, k_ref, P_ref, cfg.refine_voxel)
    i_s, i_t = crop_to_overlap(s, t, prep.center, np.eye(4), cfg.crop_angle_deg)
    if len(i_s) < 50 or len(i_t) < 50:
        return P_new
    sp, tp = s.subset(i_s).to_o3d(), t.subset(i_t).to_o3d()
    r = reg.registration_icp(sp, tp, cfg.refine_max_corr, np.eye(4), reg.TransformationEstimationPointToPlane(),
                             reg.ICPConvergenceCriteria(relative_fitness=1e-6, relative_rmse=1e-6, max_iteration=30))
    if r.fitness <= 0 or not np.isfinite(r.transformation).all():
        return P_new
    return np.asarray(r.transformation) @ P_new


def combine_paper(prep: Prepared, results: list[PairResult], cfg: CombineConfig) -> CombineResult:
    """The paper's combination: drop the lowest-fitness edge, chain, refine each attachment."""
    n = len(prep.views)
    drop = min(results, key=lambda r: r.fitness).index
    kept = [r for r in results if r.index != drop]
    poses: list[np.ndarray | None] = [None] * n
    poses[0] = np.eye(4)
    queue = deque([0])
    order = []
    while queue:
        k = queue.popleft()
        for r in kept:
            if r.target_view == k and poses[r.source_view] is None:
                new, P = r.source_view, poses[k] @ r.T
            elif r.source_view == k and poses[r.target_view] is None:
                new, P = r.target_view, poses[k] @ invert(r.T)
            else:
                continue
            if cfg.refine:
                P = refine_attachment(prep, P, new, poses[k], k, cfg)
            poses[new] = P
            order.append((new, k))
            queue.append(new)
    if any(p is None for p in poses):
        return CombineResult(chain_poses(n, results), "paper", drop, {"fallback": "disconnected"})
    return CombineResult([np.asarray(p) for p in poses], "paper", drop, {"attach_order": order})


def pairwise_consistency(prep: Prepared, poses: list[np.ndarray], results: list[PairResult],
                         cfg: CombineConfig) -> dict:
    """Fitness and inlier RMSE of every neighbour pair *as posed in the model* (loop edge included).

    This is the model's own consistency: two neighbours that the final poses put apart show up here
    whatever the pair registration claimed. Posed fitness counts every point of the source view, so it also
    falls where the neighbour does not see that part at all (a box's corner turning past a camera that looks
    from the side: half of one view's points are on a face the next view does not see). The pair's overlap
    (share within ``overlap_distance``) and its agreement (share of the overlap within the consistency
    distance) tell the two apart.
    """
    clouds = [_posed(prep, k, poses[k], cfg.consistency_voxel) for k in range(len(poses))]
    trees = [cKDTree(c.xyz.astype(np.float64)) for c in clouds]
    fit, rmse, overlap, agree = [], [], [], []
    for r in results:
        s, t = clouds[r.source_view], trees[r.target_view]
        reach = max(cfg.consistency_distance, cfg.overlap_distance)
        d, _ = t.query(s.xyz.astype(np.float64), k=1, distance_upper_bound=reach)
        inl = d < cfg.consistency_distance  # as a query bounded there counts them
        near = np.isfinite(d)
        fit.append(float(inl.mean()) if len(d) else 0.0)
        rmse.append(1000.0 * float(np.sqrt(np.mean(d[inl] ** 2))) if inl.any() else float("inf"))
        overlap.append(float(near.mean()) if len(d) else 0.0)
        agree.append(float(inl.sum() / near.sum()) if near.any() else 0.0)
    return {"posed_fitness": fit, "posed_rmse_mm": rmse,
            "mean_posed_fitness": float(np.mean(fit)), "min_posed_fitness": float(np.min(fit)),
            "mean_posed_rmse_mm": float(np.mean(rmse)),
            "posed_overlap": overlap, "posed_agreement": agree,
            "min_posed_overlap": float(np.min(overlap)), "min_posed_agreement": float(np.min(agree))}


def unmeasured_gaps(prep: Prepared, poses: list[np.ndarray], kept_edges: list[PairResult], kept: list[int],
                    cfg: CombineConfig) -> list[dict]:
    """Consecutive kept views (round the loop) that no kept pair links and that share too little as posed.

    Why: when a pair or a view is set aside, the loop composition no longer judges the poses, and the pose
    graph places the views on either side of what was set aside through the rest of the loop. Where those two
    views still overlap, their posed agreement vouches for the placement; where they do not (a box's views 76
    degrees apart once a view between them is left out), nothing measured the turn between them: only the
    full-turn constraint placed them. Returned with their overlap (share of the first view's points within
    ``overlap_distance`` of the second's, as posed) for ``AcceptCriteria.min_posed_overlap`` to judge.
    """
    ring = sorted(kept)
    if len(ring) < 2:
        return []
    linked = {frozenset((r.source_view, r.target_view)) for r in kept_edges}
    out = []
    for a, b in zip(ring, ring[1:] + ring[:1], strict=True):
        if a == b or frozenset((a, b)) in linked:
            continue
        s = _posed(prep, a, poses[a], cfg.consistency_voxel)
        t = cKDTree(_posed(prep, b, poses[b], cfg.consistency_voxel).xyz.astype(np.float64))
        d, _ = t.query(s.xyz.astype(np.float64), k=1, distance_upper_bound=cfg.overlap_distance)
        out.append({"from": prep.views[a].index, "to": prep.views[b].index,
                    "overlap": round(float(np.isfinite(d).mean()) if len(d) else 0.0, 4)})
    return out
