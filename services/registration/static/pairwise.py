"""Pairwise registration steps, each a thin, named wrapper over Open3D's legacy pipeline.

The legacy API is the fast one on CPU for voxel-down-sampled clouds (ecosystem-notes §5). Feature
matching, colour ICP and the overlap removal are the shared blocks of ``registration/blocks.py``. Every
function takes ``source`` and ``target`` with normals (and colors where used) and returns a ``PairResult`` whose
``T`` maps source points onto target points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from services.registration.blocks import (
    ColorICPConfig,
    FeatureMatchConfig,
    colored_icp,
    fpfh_features,
    ransac_feature_match,
)

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
    cfg = FeatureMatchConfig(fpfh_radius_factor=radius_factor, max_iteration=iterations, confidence=confidence)
    fs, ft = fpfh_features(source, voxel, cfg), fpfh_features(target, voxel, cfg)
    return PairResult.of(ransac_feature_match(source, target, fs, ft, max_corr, seed=seed, config=cfg), max_corr)


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
    cfg = ColorICPConfig(max_iteration=iterations, lambda_geometric=lambda_geometric, relative_fitness=1e-7,
                         relative_rmse=1e-7)
    out = colored_icp(source, target, max_corr, init, cfg)
    return PairResult(T=out.T, fitness=out.fitness, rmse=out.rmse, max_corr=max_corr)


def icp_generalized(source, target, max_corr: float, init: np.ndarray, iterations: int = 30) -> PairResult:
    crit = reg.ICPConvergenceCriteria(1e-7, 1e-7, iterations)
    est = reg.TransformationEstimationForGeneralizedICP()
    return _safe(lambda: reg.registration_generalized_icp(source, target, max_corr, init, est, crit), init, max_corr)


def information(source, target, max_corr: float, T: np.ndarray) -> np.ndarray:
    """6x6 information matrix of a pairwise result, the pose-graph edge weight."""
    return np.asarray(reg.get_information_matrix_from_point_clouds(source, target, max_corr, T))
