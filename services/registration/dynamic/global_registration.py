"""One interface over the three global registration methods: 4PCS (ours), FPFH-RANSAC and FGR (Open3D).

The paper's pair registration starts from a global alignment at 8 mm voxels with Super 4PCS, run with
overlaps 0.9, 0.85 and 0.8, the best fitness winning. ``global_register`` does exactly that for
``method="4pcs"`` and runs Open3D's FPFH-RANSAC or FGR (legacy API, the only home of both) otherwise, so
the pipeline and the benchmark can swap them. Every method's result is scored the same way - LCP and
weighted LCP of the down-sampled source against the down-sampled target at ``delta = voxel`` - so results
are comparable across overlaps and methods.

Clouds are numpy (N, 3) arrays or Open3D point clouds; normals are estimated at 2.5 x voxel when absent
(4PCS uses them for its normal filter, FPFH needs them). ``o3d.utility.random.seed(seed)`` is called
before RANSAC, which makes it reproducible with ``OMP_NUM_THREADS=1``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from time import perf_counter

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from services.registration.blocks import FeatureMatchConfig, fpfh_features, ransac_feature_match
from services.registration.dynamic.fourpcs import FourPCSConfig, register_4pcs_overlaps, score_alignment
from services.registration.dynamic.fourpcs_common import (
    GlobalResult,
    PointCloudInputError,
    as_optional_rows,
    as_xyz,
    check_transform,
)

METHODS = ("4pcs", "fpfh_ransac", "fgr")
PAPER_OVERLAPS = (0.9, 0.85, 0.8)

reg = o3d.pipelines.registration


@dataclass(frozen=True)
class GlobalRegistrationConfig:
    """Parameters of the three methods (multiples are of the voxel size), Open3D-tutorial defaults."""

    normal_radius_factor: float = 2.5
    features: FeatureMatchConfig = FeatureMatchConfig()  # FPFH (FGR and RANSAC) and RANSAC's own settings
    ransac_distance_factor: float = 1.5
    fgr_distance_factor: float = 0.5
    fourpcs_max_time_s: float = 2.0
    fourpcs_sample_size: int = 200
    # the paper runs all three overlaps; skipping the rest once a run's pose is confirmed is our speed-up
    fourpcs_skip_after_confirmed: bool = True
    fourpcs: FourPCSConfig = FourPCSConfig()


def global_register(source: np.ndarray | o3d.geometry.PointCloud, target: np.ndarray | o3d.geometry.PointCloud,
                    method: str = "4pcs", *, voxel: float = 0.008,
                    overlap: float | Sequence[float] = PAPER_OVERLAPS, seed: int = 0,
                    source_normals: np.ndarray | None = None, target_normals: np.ndarray | None = None,
                    prior_T: np.ndarray | None = None, prior_margin: float = 0.03,
                    config: GlobalRegistrationConfig | None = None) -> GlobalResult:
    """Global (initial-guess-free) ``T`` with ``target ~ T @ source``, by ``method`` at ``voxel`` metres.

    ``overlap`` is used by 4PCS only; a sequence runs 4PCS once per value and keeps the highest weighted
    LCP, as the paper does with 0.9, 0.85, 0.8 (unless ``config.fourpcs_skip_after_confirmed``, on by
    default, stops after a run whose pose was confirmed). The result's ``seconds`` include down-sampling,
    normals and features.

    ``prior_T`` (e.g. the identity for views already pre-rotated by their commanded turn) has its
    translation corrected by a translation-only ICP (its rotation is kept: that is the trusted part, and
    a free ICP would slide a can about its axis) and is returned instead of the method's answer when it
    then scores within ``prior_margin`` of it (weighted LCP): when the geometry cannot tell poses apart
    the prior is the better guess, while a clearly better fit still wins. ``extra["kept_prior"]`` says
    which happened.
    """
    cfg = config or GlobalRegistrationConfig()
    if method not in METHODS:
        raise PointCloudInputError(f"unknown global registration method {method!r}; use one of {METHODS}",
                                   code="bad_value", detail={"field": "method"})
    if not voxel > 0:
        raise PointCloudInputError(f"voxel must be > 0, got {voxel}", code="bad_value",
                                   detail={"field": "voxel"})
    t0 = perf_counter()
    src = preprocess(source, voxel, normals=source_normals, normal_radius_factor=cfg.normal_radius_factor,
                     name="source")
    tgt = preprocess(target, voxel, normals=target_normals, normal_radius_factor=cfg.normal_radius_factor,
                     name="target")
    if method == "4pcs":
        overlaps = [float(overlap)] if np.isscalar(overlap) else [float(o) for o in overlap]
        if not overlaps:
            raise PointCloudInputError("overlap list is empty", code="bad_value", detail={"field": "overlap"})
        src_xyz, tgt_xyz = np.asarray(src.points), np.asarray(tgt.points)
        src_n, tgt_n = np.asarray(src.normals), np.asarray(tgt.normals)
        runs = register_4pcs_overlaps(src_xyz, tgt_xyz, overlaps=overlaps, delta=voxel, seed=seed,
                                      max_time_s=cfg.fourpcs_max_time_s, sample_size=cfg.fourpcs_sample_size,
                                      source_normals=src_n, target_normals=tgt_n,
                                      skip_after_confirmed=cfg.fourpcs_skip_after_confirmed, config=cfg.fourpcs)
        best = max(runs, key=lambda r: r.score)
        result = replace(best, n_bases_tried=sum(r.n_bases_tried for r in runs),
                         extra={**best.extra, "scores_per_overlap": {r.overlap: r.score for r in runs}})
    else:
        T = _feature_based(src, tgt, method, voxel, seed, cfg)
        result = GlobalResult(T=T, lcp_score=0.0, n_bases_tried=0, seconds=0.0, method=method)
    lcp, weighted = score_alignment(np.asarray(src.points), np.asarray(tgt.points), result.T, voxel)
    T, kept_prior = result.T, False
    if prior_T is not None:
        prior = check_transform(prior_T, "prior_T")
        # the prior's rotation is what we trust; its translation inherits centre-estimate errors, so it is
        # corrected by a translation-only ICP (which cannot slide a can about its axis) before scoring
        src_xyz, tgt_xyz = np.asarray(src.points), np.asarray(tgt.points)
        prior = _translation_only_icp(src_xyz, cKDTree(tgt_xyz), prior, 2.0 * voxel)
        prior_lcp, prior_weighted = score_alignment(src_xyz, tgt_xyz, prior, voxel)
        if prior_weighted >= weighted - prior_margin:
            T, lcp, weighted, kept_prior = prior, prior_lcp, prior_weighted, True
    return replace(result, T=T, lcp_score=lcp, score=weighted, seconds=perf_counter() - t0,
                   extra={**result.extra, "n_source": len(src.points), "n_target": len(tgt.points),
                          "voxel": voxel, "kept_prior": kept_prior})


def preprocess(cloud: np.ndarray | o3d.geometry.PointCloud, voxel: float, *, normals: np.ndarray | None = None,
               normal_radius_factor: float = 2.5, name: str = "cloud") -> o3d.geometry.PointCloud:
    """Voxel-down-sampled copy with normals (given ones are averaged per voxel, else estimated)."""
    if isinstance(cloud, o3d.geometry.PointCloud):
        pcd = o3d.geometry.PointCloud(cloud)
        as_xyz(np.asarray(pcd.points), name, min_points=4)
        if normals is not None:
            pcd.normals = o3d.utility.Vector3dVector(as_optional_rows(normals, len(pcd.points), f"{name}_normals"))
    else:
        xyz = as_xyz(cloud, name, min_points=4)
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
        if normals is not None:
            pcd.normals = o3d.utility.Vector3dVector(as_optional_rows(normals, xyz.shape[0], f"{name}_normals"))
    down = pcd.voxel_down_sample(voxel)
    if len(down.points) < 4:
        raise PointCloudInputError(f"{name} has {len(down.points)} points after {voxel} m voxels, need 4",
                                   code="too_few_points", detail={"field": name})
    if not down.has_normals():
        down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=normal_radius_factor * voxel, max_nn=30))
    else:
        n = np.asarray(down.normals)
        down.normals = o3d.utility.Vector3dVector(n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12))
    return down


def refine_icp(source: np.ndarray | o3d.geometry.PointCloud, target: np.ndarray | o3d.geometry.PointCloud,
               T_init: np.ndarray, *, voxel: float = 0.004, max_correspondence_factor: float = 2.0,
               iterations: int = 50) -> tuple[np.ndarray, float, float]:
    """Point-to-plane ICP from ``T_init`` at ``voxel``: (T, fitness, inlier RMSE).

    A plain local refinement after a global estimate (what "success after local refinement" is judged
    with); the paper's full local stage (color ICP, GICP, overlap removal) lives in the pair-registration pipeline.
    """
    src = preprocess(source, voxel, name="source")
    tgt = preprocess(target, voxel, name="target")
    out = reg.registration_icp(src, tgt, max_correspondence_factor * voxel, check_transform(T_init, "T_init"),
                               reg.TransformationEstimationPointToPlane(),
                               reg.ICPConvergenceCriteria(max_iteration=iterations))
    return np.array(out.transformation), float(out.fitness), float(out.inlier_rmse)


def _translation_only_icp(src: np.ndarray, tgt_tree: cKDTree, T: np.ndarray, max_dist: float,
                          iterations: int = 20) -> np.ndarray:
    """``T`` with its translation refined by point-to-point ICP that keeps the rotation fixed."""
    T = T.copy()
    rotated = src @ T[:3, :3].T
    for _ in range(iterations):
        dist, idx = tgt_tree.query(rotated + T[:3, 3], k=1, distance_upper_bound=max_dist)
        ok = np.isfinite(dist)
        if ok.sum() < 3:
            break
        step = np.mean(tgt_tree.data[idx[ok]] - (rotated[ok] + T[:3, 3]), axis=0)
        T[:3, 3] += step
        if np.linalg.norm(step) < 1e-5:
            break
    return T


def _feature_based(src: o3d.geometry.PointCloud, tgt: o3d.geometry.PointCloud, method: str, voxel: float,
                   seed: int, cfg: GlobalRegistrationConfig) -> np.ndarray:
    f_src, f_tgt = fpfh_features(src, voxel, cfg.features), fpfh_features(tgt, voxel, cfg.features)
    if method == "fgr":
        opt = reg.FastGlobalRegistrationOption(maximum_correspondence_distance=cfg.fgr_distance_factor * voxel,
                                               seed=seed) if _fgr_has_seed() else \
            reg.FastGlobalRegistrationOption(maximum_correspondence_distance=cfg.fgr_distance_factor * voxel)
        out = reg.registration_fgr_based_on_feature_matching(src, tgt, f_src, f_tgt, opt)
        return np.array(out.transformation)
    out = ransac_feature_match(src, tgt, f_src, f_tgt, cfg.ransac_distance_factor * voxel, seed=seed,
                               config=cfg.features)
    return np.array(out.transformation)


def _fgr_has_seed() -> bool:
    try:
        reg.FastGlobalRegistrationOption(seed=0)
        return True
    except TypeError:
        return False
