"""Pairwise registration steps, each a thin, named wrapper over Open3D's legacy pipeline.

The legacy API is the fast one on CPU for voxel-down-sampled clouds (ecosystem-notes §5). Every function
takes ``source`` and ``target`` with normals (and colors where used) and returns a ``PairResult`` whose
``T`` maps source points onto target points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

reg = o3d.pipelines.registration


@dataclass
class PairResult:
    T: np.ndarray  # 4x4, maps source onto target
    fitness: float  # fraction of source points with a correspondence within max_corr
    rmse: float  # inlier RMSE, m
    max_corr: float  # the correspondence distance these figures were measured at

    @classmethod
    def of(cls, result: reg.RegistrationResult, max_corr: float) -> PairResult:
        return cls(
            T=np.asarray(result.transformation).copy(),
            fitness=float(result.fitness),
            rmse=float(result.inlier_rmse),
            max_corr=max_corr,
        )


def evaluate(
    source: o3d.geometry.PointCloud, target: o3d.geometry.PointCloud, T: np.ndarray, max_corr: float
) -> PairResult:
    """Fitness and inlier RMSE of ``T`` at ``max_corr`` (no optimisation)."""
    return PairResult.of(reg.evaluate_registration(source, target, max_corr, T), max_corr)


def fpfh(pcd: o3d.geometry.PointCloud, voxel: float, radius_factor: float = 5.0) -> reg.Feature:
    """FPFH features of a down-sampled cloud with normals (radius = factor x voxel, as Open3D's tutorial)."""
    return reg.compute_fpfh_feature(pcd, o3d.geometry.KDTreeSearchParamHybrid(radius=voxel * radius_factor, max_nn=100))


def global_ransac(
    source: o3d.geometry.PointCloud,
    target: o3d.geometry.PointCloud,
    voxel: float,
    *,
    seed: int,
    iterations: int = 100000,
    confidence: float = 0.999,
    radius_factor: float = 5.0,
    corr_factor: float = 1.5,
) -> PairResult:
    """FPFH feature-matching RANSAC (the paper's global registration), seeded for reproducibility."""
    max_corr = voxel * corr_factor
    fs, ft = fpfh(source, voxel, radius_factor), fpfh(target, voxel, radius_factor)
    o3d.utility.random.seed(int(seed))
    result = reg.registration_ransac_based_on_feature_matching(
        source,
        target,
        fs,
        ft,
        True,
        max_corr,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(max_corr)],
        reg.RANSACConvergenceCriteria(iterations, confidence),
    )
    return PairResult.of(result, max_corr)


def _safe(run, init: np.ndarray, max_corr: float) -> PairResult:
    """Run an Open3D ICP; when it finds no correspondence at all (Open3D raises), keep ``init``, fitness 0."""
    try:
        return PairResult.of(run(), max_corr)
    except RuntimeError:
        return PairResult(
            T=np.asarray(init, dtype=np.float64).copy(), fitness=0.0, rmse=float("inf"), max_corr=max_corr
        )


def icp_point_to_plane(source, target, max_corr: float, init: np.ndarray, iterations: int = 30) -> PairResult:
    crit = reg.ICPConvergenceCriteria(1e-7, 1e-7, iterations)
    return _safe(
        lambda: reg.registration_icp(source, target, max_corr, init, reg.TransformationEstimationPointToPlane(), crit),
        init,
        max_corr,
    )


def icp_colored(
    source, target, max_corr: float, init: np.ndarray, iterations: int = 30, lambda_geometric: float = 0.968
) -> PairResult:
    """Colored ICP (Park et al. 2017): photometric + geometric; needs colors on both and target normals."""
    crit = reg.ICPConvergenceCriteria(1e-7, 1e-7, iterations)
    est = reg.TransformationEstimationForColoredICP(lambda_geometric)
    return _safe(lambda: reg.registration_colored_icp(source, target, max_corr, init, est, crit), init, max_corr)


def icp_generalized(source, target, max_corr: float, init: np.ndarray, iterations: int = 30) -> PairResult:
    crit = reg.ICPConvergenceCriteria(1e-7, 1e-7, iterations)
    est = reg.TransformationEstimationForGeneralizedICP()
    return _safe(lambda: reg.registration_generalized_icp(source, target, max_corr, init, est, crit), init, max_corr)


def mean_spacing(pcd: o3d.geometry.PointCloud) -> float:
    """d of the paper: the mean distance from each point to its nearest neighbour in the same cloud."""
    dist = np.asarray(pcd.compute_nearest_neighbor_distance())
    return float(dist.mean()) if dist.size else 0.0


def overlap_only(
    source: o3d.geometry.PointCloud,
    target: o3d.geometry.PointCloud,
    T: np.ndarray,
) -> tuple[o3d.geometry.PointCloud, o3d.geometry.PointCloud]:
    """The paper's temporary removal of non-overlapping points.

    A source point is kept when the (transformed) target has a point within d_source of it, d being the
    cloud's mean point spacing; likewise for the target. The clouds returned are for the final
    point-to-plane step only; the full clouds are what get fused.
    """
    src_pts = np.asarray(source.points) @ T[:3, :3].T + T[:3, 3]
    tgt_pts = np.asarray(target.points)
    d_src, d_tgt = mean_spacing(source), mean_spacing(target)
    near_src = cKDTree(tgt_pts).query(src_pts, k=1, distance_upper_bound=d_src)[0] <= d_src
    near_tgt = cKDTree(src_pts).query(tgt_pts, k=1, distance_upper_bound=d_tgt)[0] <= d_tgt
    return (
        source.select_by_index(np.flatnonzero(near_src)),
        target.select_by_index(np.flatnonzero(near_tgt)),
    )


def information(source, target, max_corr: float, T: np.ndarray) -> np.ndarray:
    """6x6 information matrix of a pairwise result, the pose-graph edge weight."""
    return np.asarray(reg.get_information_matrix_from_point_clouds(source, target, max_corr, T))
