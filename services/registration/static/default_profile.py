"""The ``default`` profile's alignment: the arm's believed poses as the prior, refined pair by pair.

Per pair (each scan against scan 0): dense RGB-D odometry (full-resolution image pyramid) from the prior, seeded by
the reverse odometry on coarser images (``reverse_seed``), checked
(fitness, inlier RMSE, and a correction the arm's accuracy can explain: ``plausibility``); a pair that fails
tries GICP from the prior, and only then a search confined to the plausible window (``window_search``: ICP
from a grid of starts on the table-free clouds, refined, scored on the table-free clouds). A result that
fails its check or lies outside the window is returned unverified, with the reason, and is not fused.
Optional pose graph with the edges to scan 0 as the spanning tree. See docs/static-registration.md.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import open3d as o3d

from common.geometry import invert, transform_error, transform_points
from common.messages import RGBDFrame
from services.registration.cloud import downsample, to_o3d

from . import pairwise as pw
from .config import StaticConfig
from .odometry import OdometryImage, pinhole, rgbd_image, rgbd_odometry
from .odometry_window import ImageWindow, odometry_window
from .plausibility import correction_bound, implausibility, plausible
from .posegraph import optimise
from .result import PairOutcome, Stopwatch
from .scans import MIN_SCAN_POINTS, Scan, roi_mask, strip_table
from .window_search import window_search


@dataclass
class PriorScan:
    """One scan's clouds and image for the prior-seeded path; what only the fallbacks need is built lazily."""

    cfg: StaticConfig
    pcd: o3d.geometry.PointCloud  # the ROI-cropped scan in its camera frame
    check: o3d.geometry.PointCloud  # ``check_voxel`` copy the pair check measures on
    intrinsic: o3d.camera.PinholeCameraIntrinsic  # of the decimated image
    make_image: Callable[[], OdometryImage] = field(repr=False)
    make_seed_image: Callable[[], tuple[OdometryImage, o3d.camera.PinholeCameraIntrinsic]] | None = field(
        default=None, repr=False
    )
    _table_free: tuple[o3d.geometry.PointCloud, o3d.geometry.PointCloud] | None = field(default=None, repr=False)

    @cached_property
    def image(self) -> OdometryImage:
        """The decimated RGB-D image for odometry (built on first use)."""
        return self.make_image()

    @cached_property
    def seed_image(self) -> tuple[OdometryImage, o3d.camera.PinholeCameraIntrinsic]:
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
    correction of the arm's relative pose that the arm's accuracy can explain (plausibility.py)."""
    res = pw.evaluate(src, tgt, T, cfg.check_voxel * cfg.check_corr_factor)
    return res, rejection(res, T, prior, cfg) is None


def rejection(res: pw.PairResult, T: np.ndarray, prior: np.ndarray, cfg: StaticConfig,
              object_fitness: float | None = None) -> str | None:
    """Why a checked result must not be fused (implausible first: it overrules any fit), or None."""
    why = implausibility(T, prior, cfg)
    if why is not None:
        return why
    fits = [res.fitness] + ([] if object_fitness is None else [object_fitness])
    if min(fits) < cfg.min_fitness or res.rmse > cfg.max_rmse:
        obj = "" if object_fitness is None else f", object fitness {object_fitness:.2f}"
        return (f"unverified: fitness {res.fitness:.2f}{obj} (min {cfg.min_fitness}), inlier RMSE "
                f"{res.rmse * 1e3:.2f} mm (max {cfg.max_rmse * 1e3:.1f} mm)")
    return None


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
        backend=cfg.odometry_backend,
    )


def reverse_seed(src: PriorScan, tgt: PriorScan, prior: np.ndarray, cfg: StaticConfig) -> np.ndarray:
    """The forward odometry's start: the inverse of the reverse odometry (target onto source) run from the
    inverted prior on the coarser seed images, or the prior itself when that pass fails or jumps further
    than the arm's error can explain.

    Why: the two directions take their correspondences from different images, so they stall in different
    places; from a prior several mm off the forward run alone stopped in a nearby minimum on 3 of 12 milk
    pairs (up to 8 mm) where the reverse run reached the true one's basin, and the forward run from there
    converges (docs/static-registration.md, step 3)."""
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
        backend=cfg.odometry_backend,
    )
    if not ok:
        return prior
    seed = invert(T_rev)
    return seed if plausible(seed, prior, cfg) else prior


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
    step_m, step_deg = transform_error(refined, T)
    if (after < before + cfg.object_min_gain or not plausible(refined, prior, cfg)
            or step_m > cfg.object_max_step_m or step_deg > cfg.object_max_step_deg):
        return None
    return refined


def _polish_on_object(src: PriorScan, tgt: PriorScan, T: np.ndarray, cfg: StaticConfig) -> np.ndarray:
    """``T`` refined by point-to-plane ICP on the table-free ``object_voxel`` clouds (the window search ran at
    ``global_object_voxel``); unchanged when a scan has too little object to refine on."""
    if src.object is None or tgt.object is None:
        return T
    for corr in cfg.object_corr:
        T = pw.icp_point_to_plane(src.object, tgt.object, corr, T, cfg.object_iterations).T
    return T


def _local(src: PriorScan, tgt: PriorScan, T: np.ndarray, prior: np.ndarray, method: str, cfg: StaticConfig
           ) -> PairOutcome:
    """The local outcome of ``T``: checked (``verified``), and object-refined when it passed and that helps."""
    res, passed = _check(src.check, tgt.check, T, prior, cfg)
    if not passed:
        return PairOutcome(T, "local", method, res, False, rejection(res, T, prior, cfg))
    refined = refine_on_object(src, tgt, T, prior, cfg)
    if refined is not None:
        res_r, passed_r = _check(src.check, tgt.check, refined, prior, cfg)
        if passed_r:
            return PairOutcome(refined, "local", f"{method}+object_icp", res_r, True)
    obj = _object_fitness(src, tgt, T, cfg)
    if obj is not None and obj < cfg.min_fitness:
        return PairOutcome(T, "local", method, res, False, rejection(res, T, prior, cfg, object_fitness=obj))
    return PairOutcome(T, "local", method, res, True)


def _object_fitness(src: PriorScan, tgt: PriorScan, T: np.ndarray, cfg: StaticConfig) -> float | None:
    """Fitness of ``T`` on the table-free clouds at the check's correspondence distance, or None when a scan has
    too little object to tell.

    Why: the table fills most of a scan and a plane lets the camera slide; from a prior several cm off, GICP
    can stop where the table fits and the object does not (a realistic milk pair: 61 mm / 2.3 deg off the
    truth, whole-scan fitness passing). A wide plausible window (an arm stated as inaccurate) cannot catch
    that; the object can. A result the object refinement raised was measured on the object already."""
    if src.object is None or tgt.object is None:
        return None
    return pw.evaluate(src.object, tgt.object, T, cfg.check_voxel * cfg.check_corr_factor).fitness


def register_pair(src: PriorScan, tgt: PriorScan, prior: np.ndarray, cfg: StaticConfig, seed: int,
                  up: np.ndarray | None = None, sw: Stopwatch | None = None) -> PairOutcome:
    """Local first (RGB-D odometry from the reverse seed, then GICP from the arm's prior), each refined on the
    object when that helps, the window search (``window_search.py``) only when both fail. The check always
    measures the correction against the arm's prior; ``up`` is the table normal in the target camera's frame
    (the search's yaw axis), None when unknown."""
    candidates = []
    with sw("odometry") if sw is not None else nullcontext():
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
    return _fallback(src, tgt, prior, cfg, seed, candidates, up)


def _fallback(src: PriorScan, tgt: PriorScan, prior: np.ndarray, cfg: StaticConfig, seed: int,
              candidates: list[PairOutcome], up: np.ndarray | None) -> PairOutcome:
    """The arm's prior failed locally: ICP from a fixed grid of starts inside the plausible window, on the
    table-free clouds; the best few are refined on the object and polished by odometry. Every candidate, the
    local ones too, is scored on the table-free clouds, and one outside the window is never kept, however
    well it fits. Deterministic: the starts are a grid, the table plane's RANSAC is seeded."""
    src_global, src_check = src.table_free(seed)
    tgt_global, tgt_check = tgt.table_free(seed + 1)
    corr = cfg.check_voxel * cfg.check_corr_factor
    starts = window_search(src_global, tgt_global, src_check, tgt_check, prior, cfg, up)
    scored: list[tuple[pw.PairResult, PairOutcome]] = []
    for c in candidates:
        if plausible(c.T, prior, cfg):
            scored.append((pw.evaluate(src_check, tgt_check, c.T, corr), c))
    for T in starts[: cfg.search_refine_top]:
        T = _polish_on_object(src, tgt, T, cfg)
        ok, T_odo = _odometry(src, tgt, T, cfg)
        if ok and plausible(T_odo, prior, cfg):
            T = T_odo
        if not plausible(T, prior, cfg):
            continue
        check = pw.evaluate(src.check, tgt.check, T, corr)
        scored.append((pw.evaluate(src_check, tgt_check, T, corr), PairOutcome(T, "global", "window_search+icp",
                                                                               check, False)))
    if not scored:
        res = pw.evaluate(src.check, tgt.check, prior, corr)
        why = ("unverified: no candidate inside the plausible window "
               f"({correction_bound(prior, cfg).m * 1e3:.1f} mm / {correction_bound(prior, cfg).deg:.2f} deg) fits")
        return PairOutcome(prior, "global", "window_search", res, False, why)
    # ties (equal rounded object fitness) go to the lower RMSE, then to the earlier candidate: a stable order
    order = sorted(range(len(scored)), key=lambda i: (-round(scored[i][0].fitness, 2), scored[i][0].rmse, i))
    obj_res, best = scored[order[0]]
    best.reason = rejection(best.check, best.T, prior, cfg, object_fitness=obj_res.fitness)
    best.verified = best.reason is None
    return best


def _prepare(scan: Scan, frame: RGBDFrame, cfg: StaticConfig, window: ImageWindow | None) -> PriorScan:
    pcd = to_o3d(scan.pts_cam.xyz, scan.pts_cam.rgb)
    seed_step = cfg.odometry_step * cfg.odometry_seed_step
    return PriorScan(
        cfg=cfg,
        pcd=pcd,
        check=downsample(pcd, cfg.check_voxel, normals=False),
        intrinsic=pinhole(frame, cfg.odometry_step, window),
        make_image=lambda: rgbd_image(frame, step=cfg.odometry_step, depth_min=cfg.depth_min, depth_max=cfg.depth_max,
                                      window=window, backend=cfg.odometry_backend,
                                      levels=len(cfg.odometry_iterations)),
        make_seed_image=None if cfg.odometry_seed_iterations is None else lambda: (
            rgbd_image(frame, step=seed_step, depth_min=cfg.depth_min, depth_max=cfg.depth_max, window=window,
                       backend=cfg.odometry_backend, levels=len(cfg.odometry_seed_iterations)),
            pinhole(frame, seed_step, window),
        ),
    )


def crop_to_roi(scans: list[Scan], seed_base: np.ndarray | None, cfg: StaticConfig) -> None:
    """Keep each scan's points within the ROI around the seed (in place; a scan left too small is kept whole)."""
    for s in scans:
        if seed_base is not None and cfg.roi_radius is not None:
            keep = roi_mask(transform_points(s.T_believed, s.pts_cam.xyz), seed_base, cfg)
            if keep.sum() >= MIN_SCAN_POINTS:
                s.pts_cam = s.pts_cam.subset(keep)


def _up_in(scan: Scan, cfg: StaticConfig) -> np.ndarray | None:
    """The table normal (``expected_up``, base) in the scan's believed camera frame, or None when unknown."""
    if cfg.expected_up is None:
        return None
    return scan.T_believed[:3, :3].T @ np.asarray(cfg.expected_up, dtype=np.float64)


def prepare(scans: list[Scan], frames: list[RGBDFrame], cfg: StaticConfig,
            window: ImageWindow | None = None) -> list[PriorScan]:
    """Each scan's clouds and images for the prior-seeded path (what only the fallbacks need, lazily); the
    odometry's images cut to ``window`` (None: the whole image)."""
    return [_prepare(s, f, cfg, window) for s, f in zip(scans, frames, strict=True)]


def view_window(scans: list[Scan], frames: list[RGBDFrame], seed_base: np.ndarray | None,
                cfg: StaticConfig) -> ImageWindow | None:
    """The view's odometry window from its scans' ROI pixels (after ``crop_to_roi``), None for the whole image."""
    k = frames[0].intrinsics
    has_roi = seed_base is not None and cfg.roi_radius is not None
    return odometry_window([s.pts_cam.pixel for s in scans], k.width, k.height, has_roi, cfg)


def register(
    scans: list[Scan], frames: list[RGBDFrame], seed_base: np.ndarray | None, cfg: StaticConfig, sw: Stopwatch
) -> tuple[list[np.ndarray], list[PairOutcome | None]]:
    """Camera poses relative to scan 0 (T_c0_cj), from the arm's poses refined pairwise."""
    with sw("roi"):
        crop_to_roi(scans, seed_base, cfg)
    if len(scans) == 1:
        return [np.eye(4)], [None]
    with sw("preprocess"):
        data = prepare(scans, frames, cfg, view_window(scans, frames, seed_base, cfg))
    with sw("register"):
        edges, outcomes = [], {}
        for j in range(1, len(scans)):
            for i in range(j) if cfg.use_pose_graph else (0,):
                prior = invert(scans[i].T_believed) @ scans[j].T_believed
                out = register_pair(data[j], data[i], prior, cfg, cfg.seed + 31 * j + i, up=_up_in(scans[i], cfg),
                                    sw=sw)
                outcomes[(j, i)] = out
                if cfg.use_pose_graph:
                    corr = cfg.check_voxel * cfg.check_corr_factor
                    edges.append((j, i, out.T, pw.information(data[j].check, data[i].check, corr, out.T)))
    with sw("pose_graph"):
        initial = [np.eye(4)] + [outcomes[(j, 0)].T for j in range(1, len(scans))]
        corr = cfg.check_voxel * cfg.check_corr_factor
        poses = optimise(len(scans), edges, initial, corr) if cfg.use_pose_graph and len(scans) > 2 else initial
    return poses, [None] + [outcomes[(j, 0)] for j in range(1, len(scans))]
