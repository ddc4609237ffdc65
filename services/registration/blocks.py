"""The registration building blocks, each written once: FPFH + RANSAC, colour ICP, the paper's overlap removal.

The static stage (``static/``), the dynamic pair registration (``dynamic/``) and the model library's
``find`` (``services/library/matching.py``) all match features, refine with colour ICP or drop
non-overlapping points; they call these functions with their own settings (a config dataclass each), so
a change to how a block works is made in one place. Open3D's legacy API is used throughout: it is the
only home of FPFH-RANSAC and colour ICP, and the fast one on CPU for down-sampled clouds
(ecosystem-notes §5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from services.registration.cloud import o3d_seeded

reg = o3d.pipelines.registration


# ------------------------------------------------------------------------------ FPFH + RANSAC

@dataclass(frozen=True)
class FeatureMatchConfig:
    """FPFH + RANSAC settings; Open3D-tutorial defaults (the FPFH radius is a multiple of the voxel)."""

    fpfh_radius_factor: float = 5.0
    fpfh_max_nn: int = 100
    max_iteration: int = 100_000
    confidence: float = 0.999
    edge_length_similarity: float = 0.9  # CorrespondenceCheckerBasedOnEdgeLength
    ransac_n: int = 3

    def __post_init__(self) -> None:
        if not (self.fpfh_radius_factor > 0 and self.fpfh_max_nn >= 1):
            raise ValueError(f"FPFH needs a positive radius factor and max_nn >= 1, got "
                             f"{self.fpfh_radius_factor} and {self.fpfh_max_nn}")
        if not (self.max_iteration >= 1 and 0.0 < self.confidence <= 1.0):
            raise ValueError(f"RANSAC needs max_iteration >= 1 and confidence in (0, 1], got "
                             f"{self.max_iteration} and {self.confidence}")
        if not (0.0 < self.edge_length_similarity <= 1.0 and self.ransac_n >= 3):
            raise ValueError(f"edge_length_similarity must be in (0, 1] and ransac_n >= 3, got "
                             f"{self.edge_length_similarity} and {self.ransac_n}")


def fpfh_features(pcd: o3d.geometry.PointCloud, voxel: float,
                  config: FeatureMatchConfig = FeatureMatchConfig()) -> reg.Feature:
    """FPFH features of a down-sampled cloud with normals, radius ``fpfh_radius_factor`` x ``voxel``."""
    param = o3d.geometry.KDTreeSearchParamHybrid(radius=config.fpfh_radius_factor * voxel,
                                                 max_nn=config.fpfh_max_nn)
    return reg.compute_fpfh_feature(pcd, param)


def ransac_feature_match(source: o3d.geometry.PointCloud, target: o3d.geometry.PointCloud,
                         source_features: reg.Feature, target_features: reg.Feature, max_corr: float, *,
                         seed: int, config: FeatureMatchConfig = FeatureMatchConfig()
                         ) -> reg.RegistrationResult:
    """RANSAC over mutual FPFH matches (point-to-point fits, edge-length and distance checks at ``max_corr``).

    Open3D's random generator is seeded first (and held, ``cloud.o3d_seeded``), which makes the result
    reproducible with ``OMP_NUM_THREADS=1``; the seed is folded into Open3D's 31-bit range.
    """
    with o3d_seeded(seed):
        return reg.registration_ransac_based_on_feature_matching(
            source, target, source_features, target_features, True, max_corr,
            reg.TransformationEstimationPointToPoint(False), config.ransac_n,
            [reg.CorrespondenceCheckerBasedOnEdgeLength(config.edge_length_similarity),
             reg.CorrespondenceCheckerBasedOnDistance(max_corr)],
            reg.RANSACConvergenceCriteria(config.max_iteration, config.confidence))


# ------------------------------------------------------------------------------ colour ICP

@dataclass(frozen=True)
class ColorICPConfig:
    """Colour ICP (Park et al. 2017) settings; ``lambda_geometric`` weighs geometry against colour."""

    max_iteration: int = 30
    lambda_geometric: float = 0.968  # Open3D's default
    relative_fitness: float = 1e-6
    relative_rmse: float = 1e-6

    def __post_init__(self) -> None:
        if self.max_iteration < 1 or not 0.0 <= self.lambda_geometric <= 1.0:
            raise ValueError(f"colour ICP needs max_iteration >= 1 and lambda_geometric in [0, 1], got "
                             f"{self.max_iteration} and {self.lambda_geometric}")
        if self.relative_fitness < 0 or self.relative_rmse < 0:
            raise ValueError("relative_fitness and relative_rmse must be >= 0")


@dataclass(frozen=True)
class ICPOutcome:
    """One ICP run: ``T`` (source onto target), its fitness and inlier RMSE, and whether it succeeded.

    A failed run (Open3D raised, found no correspondence, or returned a non-finite matrix) carries the
    initial ``T`` back, with fitness 0 and RMSE inf, so a caller can always go on from ``T``.
    """

    T: np.ndarray
    fitness: float
    rmse: float
    ok: bool


def colored_icp(source: o3d.geometry.PointCloud, target: o3d.geometry.PointCloud, max_corr: float,
                init: np.ndarray, config: ColorICPConfig = ColorICPConfig()) -> ICPOutcome:
    """Colour ICP from ``init``; needs colours on both clouds and normals on the target."""
    failed = ICPOutcome(np.asarray(init, dtype=np.float64).copy(), 0.0, float("inf"), False)
    crit = reg.ICPConvergenceCriteria(relative_fitness=config.relative_fitness,
                                      relative_rmse=config.relative_rmse, max_iteration=config.max_iteration)
    try:
        r = reg.registration_colored_icp(source, target, max_corr, init,
                                         reg.TransformationEstimationForColoredICP(config.lambda_geometric), crit)
    except RuntimeError:  # Open3D raises when it finds no correspondence at all: the run failed, init stands
        return failed
    T = np.asarray(r.transformation)
    if r.fitness <= 0.0 or not np.isfinite(T).all():
        return failed
    return ICPOutcome(T.copy(), float(r.fitness), float(r.inlier_rmse), True)


# ------------------------------------------------------------------------------ overlap removal

def mean_spacing(pcd: o3d.geometry.PointCloud) -> float:
    """d of the paper: the mean distance from each point to its nearest neighbour in the same cloud."""
    dist = np.asarray(pcd.compute_nearest_neighbor_distance())
    return float(dist.mean()) if dist.size else 0.0


def overlap_only(source: o3d.geometry.PointCloud, target: o3d.geometry.PointCloud, T: np.ndarray,
                 multiplier: float = 1.0) -> tuple[o3d.geometry.PointCloud, o3d.geometry.PointCloud]:
    """The paper's temporary removal of non-overlapping points (static II-B and dynamic II-C-2).

    "Non-overlapping points are defined as not within d of points in the opposing cloud, where d is the
    average distance between points within the point cloud": a source point (after ``T``) is kept when
    the target has a point within ``multiplier`` x d_source of it, a target point when the source has one
    within ``multiplier`` x d_target. The static stage uses multiplier 1; the dynamic local loop 3, 2, 1
    ("a multiplier determines how far away a point can be while being considered overlapping as a
    function of the average nearest neighbor distance in a cloud"). The clouds returned are for a
    refinement step only; the full clouds are what get fused.
    """
    if not multiplier > 0:
        raise ValueError(f"overlap multiplier must be positive, got {multiplier}")
    src_pts = np.asarray(source.points) @ T[:3, :3].T + T[:3, 3]
    tgt_pts = np.asarray(target.points)
    r_src, r_tgt = multiplier * mean_spacing(source), multiplier * mean_spacing(target)
    near_src = cKDTree(tgt_pts).query(src_pts, k=1, distance_upper_bound=r_src)[0] <= r_src
    near_tgt = cKDTree(src_pts).query(tgt_pts, k=1, distance_upper_bound=r_tgt)[0] <= r_tgt
    return (
        source.select_by_index(np.flatnonzero(near_src)),
        target.select_by_index(np.flatnonzero(near_tgt)),
    )
