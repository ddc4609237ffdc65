"""The ``default`` profile's alignment: the arm's believed poses as the prior, refined pair by pair.

Per pair (each scan against scan 0): dense RGB-D odometry (full-resolution image pyramid) from the prior, seeded by
the reverse odometry on coarser images (``reverse_seed``), checked
(fitness, inlier RMSE, size of the correction); a pair that fails tries GICP from the prior, and only then
global registration (FPFH RANSAC on the table-free clouds, refined, scored on the table-free clouds).
Optional pose graph with the edges to scan 0 as the spanning tree. See docs/static-registration.md.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import open3d as o3d

from common.geometry import invert, transform_error, transform_points
from common.messages import RGBDFrame
from services.registration.cloud import downsample, to_o3d

from . import pairwise as pw
from .config import StaticConfig
from .odometry import pinhole, rgbd_image, rgbd_odometry
from .posegraph import optimise
from .result import PairOutcome, Stopwatch
from .scans import MIN_SCAN_POINTS, Scan, roi_mask, strip_table


@dataclass
class PriorScan:
    """One scan's clouds and image for the prior-seeded path; what only the fallbacks need is built lazily."""

    cfg: StaticConfig
    pcd: o3d.geometry.PointCloud  # the ROI-cropped scan in its camera frame
    check: o3d.geometry.PointCloud  # ``check_voxel`` copy the pair check measures on
    intrinsic: o3d.camera.PinholeCameraIntrinsic  # of the decimated image
    make_image: Callable[[], o3d.geometry.RGBDImage] = field(repr=False)
    make_seed_image: Callable[[], tuple[o3d.geometry.RGBDImage, o3d.camera.PinholeCameraIntrinsic]] | None = field(
        default=None, repr=False
    )
    _table_free: tuple[o3d.geometry.PointCloud, o3d.geometry.PointCloud] | None = field(default=None, repr=False)

    @cached_property
    def image(self) -> o3d.geometry.RGBDImage:
        """The decimated RGB-D image for odometry (built on first use)."""
        return self.make_image()

    @cached_property
    def seed_image(self) -> tuple[o3d.geometry.RGBDImage, o3d.camera.PinholeCameraIntrinsic]:
        """The coarser RGB-D image (and its intrinsics) of the reverse seed pass (built on first use)."""
        if self.make_seed_image is None:
            raise ValueError("this scan was prepared without a seed image (odometry_seed_iterations is None)")
        return self.make_seed_image()

    @cached_property
    def object(self) -> o3d.geometry.PointCloud | None:
        """The scan without its table at ``object_voxel``, with normals (the object refinement's cloud), or None
        when too little is left to refine on."""
        obj = downsample(strip_table(self.pcd, self.cfg, self.cfg.seed), self.cfg.object_voxel, toward=np.zeros(3))
        return obj if len(obj.points) >= self.cfg.object_min_points else None

    @cached_property
    def levels(self) -> list[o3d.geometry.PointCloud]:
        """The GICP pyramid (``local_voxels``), only when odometry fails its check."""
        return [downsample(self.pcd, v, toward=np.zeros(3)) for v in self.cfg.local_voxels]

    def table_free(self, seed: int) -> tuple[o3d.geometry.PointCloud, o3d.geometry.PointCloud]:
        """(global-voxel, check-voxel) copies of the scan without its table, for the global fallback (the
        table makes false high-overlap matches); built once, with the RANSAC seed of the first call."""
        if self._table_free is None:
            obj = strip_table(self.pcd, self.cfg, seed)
            self._table_free = (
                downsample(obj, self.cfg.global_object_voxel, toward=np.zeros(3)),
                downsample(obj, self.cfg.check_voxel, normals=False),
            )
        return self._table_free


def _check(
    src: o3d.geometry.PointCloud, tgt: o3d.geometry.PointCloud, T: np.ndarray, prior: np.ndarray, cfg: StaticConfig
) -> tuple[pw.PairResult, bool]:
    """Measure a candidate on the check clouds; it passes with enough overlap, a small residual, and a
    correction of the arm's relative pose that the arm's error can explain."""
    res = pw.evaluate(src, tgt, T, cfg.check_voxel * cfg.check_corr_factor)
    dt, dr = transform_error(T, prior)
    ok = (
        res.fitness >= cfg.min_fitness
        and res.rmse <= cfg.max_rmse
        and dt <= cfg.max_correction_m
        and dr <= cfg.max_correction_deg
    )
    return res, ok


def _gicp_pyramid(src: PriorScan, tgt: PriorScan, cfg: StaticConfig, init: np.ndarray) -> np.ndarray:
    T = init
    for k, v in enumerate(cfg.local_voxels):
        T = pw.icp_generalized(src.levels[k], tgt.levels[k], v * cfg.local_corr_factor, T, cfg.local_iterations).T
    return T


def _odometry(src: PriorScan, tgt: PriorScan, init: np.ndarray, cfg: StaticConfig) -> tuple[bool, np.ndarray]:
    return rgbd_odometry(
        src.image,
        tgt.image,
        src.intrinsic,
        init,
        iterations=cfg.odometry_iterations,
        max_depth_diff=cfg.odometry_max_depth_diff,
        depth_min=cfg.depth_min,
        depth_max=cfg.depth_max,
        hybrid=cfg.odometry_hybrid,
    )


def reverse_seed(src: PriorScan, tgt: PriorScan, prior: np.ndarray, cfg: StaticConfig) -> np.ndarray:
    """The forward odometry's start: the inverse of the reverse odometry (target onto source) run from the
    inverted prior on the coarser seed images, or the prior itself when that pass fails or jumps further
    than the arm's error can explain.

    Why: the two directions take their correspondences from different images, so they stall in different
    places; from a prior several mm off the forward run alone stopped in a nearby minimum on 3 of 12 milk
    pairs (up to 8 mm) where the reverse run reached the true one's basin, and the forward run from there
    converges (docs/static-registration.md, BENCHMARKS.md "session 6")."""
    if cfg.odometry_seed_iterations is None:
        return prior
    (src_img, intrinsic), (tgt_img, _) = src.seed_image, tgt.seed_image
    ok, T_rev = rgbd_odometry(
        tgt_img,
        src_img,
        intrinsic,
        invert(prior),
        iterations=cfg.odometry_seed_iterations,
        max_depth_diff=cfg.odometry_max_depth_diff,
        depth_min=cfg.depth_min,
        depth_max=cfg.depth_max,
        hybrid=cfg.odometry_hybrid,
    )
    if not ok:
        return prior
    seed = invert(T_rev)
    dt, dr = transform_error(seed, prior)
    return seed if dt <= cfg.max_correction_m and dr <= cfg.max_correction_deg else prior


def refine_on_object(src: PriorScan, tgt: PriorScan, T: np.ndarray, prior: np.ndarray, cfg: StaticConfig
                     ) -> np.ndarray | None:
    """``T`` refined by point-to-plane ICP on the table-free clouds, or None when that does not raise the object
    fitness by ``object_min_gain`` (or jumps further than the arm's error can explain).

    Why: the table fills most of a scan, so the odometry and the check both weigh the table, and a plane lets
    the camera slide and tilt along it; a result stalled off the true pose can score as well as the truth on
    the whole scan while the object, the only thing the view is for, is visibly doubled (config.py)."""
    if not cfg.object_refine or src.object is None or tgt.object is None:
        return None
    before = pw.evaluate(src.object, tgt.object, T, cfg.object_score_corr).fitness
    refined = T
    for corr in cfg.object_corr:
        refined = pw.icp_point_to_plane(src.object, tgt.object, corr, refined, cfg.object_iterations).T
    after = pw.evaluate(src.object, tgt.object, refined, cfg.object_score_corr).fitness
    dt, dr = transform_error(refined, prior)
    if after < before + cfg.object_min_gain or dt > cfg.max_correction_m or dr > cfg.max_correction_deg:
        return None
    return refined


def _local(src: PriorScan, tgt: PriorScan, T: np.ndarray, prior: np.ndarray, method: str, cfg: StaticConfig
           ) -> PairOutcome:
    """The local outcome of ``T``: checked (``verified``), and object-refined when it passed and that helps."""
    res, passed = _check(src.check, tgt.check, T, prior, cfg)
    if not passed:
        return PairOutcome(T, "local", method, res, False)
    refined = refine_on_object(src, tgt, T, prior, cfg)
    if refined is not None:
        res_r, passed_r = _check(src.check, tgt.check, refined, prior, cfg)
        if passed_r:
            return PairOutcome(refined, "local", f"{method}+object_icp", res_r, True)
    return PairOutcome(T, "local", method, res, True)


def register_pair(src: PriorScan, tgt: PriorScan, prior: np.ndarray, cfg: StaticConfig, seed: int) -> PairOutcome:
    """Local first (RGB-D odometry from the reverse seed, then GICP from the arm's prior), each refined on the
    object when that helps, global only when both fail. The check always measures the correction against the
    arm's prior."""
    candidates = []
    ok, T = _odometry(src, tgt, reverse_seed(src, tgt, prior, cfg), cfg)
    if ok:
        out = _local(src, tgt, T, prior, "rgbd_odometry", cfg)
        if out.verified:
            return out
        candidates.append(out)
    out = _local(src, tgt, _gicp_pyramid(src, tgt, cfg, prior), prior, "icp", cfg)
    if out.verified:
        return out
    candidates.append(out)
    return _global(src, tgt, cfg, seed, candidates)


def _global(src: PriorScan, tgt: PriorScan, cfg: StaticConfig, seed: int, candidates: list[PairOutcome]) -> PairOutcome:
    """The arm's prior failed: FPFH RANSAC on the table-free clouds (a few seeds), each refined by GICP and
    polished by odometry; every candidate, the local ones too, is scored on the table-free clouds."""
    src_global, src_check = src.table_free(seed)
    tgt_global, tgt_check = tgt.table_free(seed + 1)
    corr = cfg.check_voxel * cfg.check_corr_factor
    scored = []
    for c in candidates:
        scored.append((pw.evaluate(src_check, tgt_check, c.T, corr), c))
    for k in range(cfg.global_attempts):
        glob = pw.global_ransac(
            src_global,
            tgt_global,
            cfg.global_object_voxel,
            seed=seed + 1000 * k,
            iterations=cfg.ransac_iterations,
            confidence=cfg.ransac_confidence,
            radius_factor=cfg.fpfh_radius_factor,
            corr_factor=cfg.ransac_corr_factor,
        )
        T = _gicp_pyramid(src, tgt, cfg, glob.T)
        ok, T_odo = _odometry(src, tgt, T, cfg)
        dt, dr = transform_error(T_odo, T)
        if ok and dt <= cfg.max_correction_m and dr <= cfg.max_correction_deg:
            T = T_odo
        check = pw.evaluate(src.check, tgt.check, T, corr)
        scored.append(
            (
                pw.evaluate(src_check, tgt_check, T, corr),
                PairOutcome(T, "global", "fpfh+icp", check, False),
            )
        )
    obj_res, best = max(scored, key=lambda sc: (round(sc[0].fitness, 2), -sc[0].rmse))
    best.verified = bool(
        obj_res.fitness >= cfg.min_fitness and best.check.fitness >= cfg.min_fitness and best.check.rmse <= cfg.max_rmse
    )
    return best


def _prepare(scan: Scan, frame: RGBDFrame, cfg: StaticConfig) -> PriorScan:
    pcd = to_o3d(scan.pts_cam.xyz, scan.pts_cam.rgb)
    seed_step = cfg.odometry_step * cfg.odometry_seed_step
    return PriorScan(
        cfg=cfg,
        pcd=pcd,
        check=downsample(pcd, cfg.check_voxel, normals=False),
        intrinsic=pinhole(frame, cfg.odometry_step),
        make_image=lambda: rgbd_image(frame, step=cfg.odometry_step, depth_min=cfg.depth_min, depth_max=cfg.depth_max),
        make_seed_image=None if cfg.odometry_seed_iterations is None else lambda: (
            rgbd_image(frame, step=seed_step, depth_min=cfg.depth_min, depth_max=cfg.depth_max),
            pinhole(frame, seed_step),
        ),
    )


def crop_to_roi(scans: list[Scan], seed_base: np.ndarray | None, cfg: StaticConfig) -> None:
    """Keep each scan's points within the ROI around the seed (in place; a scan left too small is kept whole)."""
    for s in scans:
        if seed_base is not None and cfg.roi_radius is not None:
            keep = roi_mask(transform_points(s.T_believed, s.pts_cam.xyz), seed_base, cfg)
            if keep.sum() >= MIN_SCAN_POINTS:
                s.pts_cam = s.pts_cam.subset(keep)


def prepare(scans: list[Scan], frames: list[RGBDFrame], cfg: StaticConfig) -> list[PriorScan]:
    """Each scan's clouds and images for the prior-seeded path (what only the fallbacks need, lazily)."""
    return [_prepare(s, f, cfg) for s, f in zip(scans, frames, strict=True)]


def register(
    scans: list[Scan], frames: list[RGBDFrame], seed_base: np.ndarray | None, cfg: StaticConfig, sw: Stopwatch
) -> tuple[list[np.ndarray], list[PairOutcome | None]]:
    """Camera poses relative to scan 0 (T_c0_cj), from the arm's poses refined pairwise."""
    with sw("roi"):
        crop_to_roi(scans, seed_base, cfg)
    if len(scans) == 1:
        return [np.eye(4)], [None]
    with sw("preprocess"):
        data = prepare(scans, frames, cfg)
    with sw("register"):
        edges, outcomes = [], {}
        for j in range(1, len(scans)):
            for i in range(j) if cfg.use_pose_graph else (0,):
                prior = invert(scans[i].T_believed) @ scans[j].T_believed
                out = register_pair(data[j], data[i], prior, cfg, cfg.seed + 31 * j + i)
                outcomes[(j, i)] = out
                if cfg.use_pose_graph:
                    corr = cfg.check_voxel * cfg.check_corr_factor
                    edges.append((j, i, out.T, pw.information(data[j].check, data[i].check, corr, out.T)))
    with sw("pose_graph"):
        initial = [np.eye(4)] + [outcomes[(j, 0)].T for j in range(1, len(scans))]
        corr = cfg.check_voxel * cfg.check_corr_factor
        poses = optimise(len(scans), edges, initial, corr) if cfg.use_pose_graph and len(scans) > 2 else initial
    return poses, [None] + [outcomes[(j, 0)] for j in range(1, len(scans))]
