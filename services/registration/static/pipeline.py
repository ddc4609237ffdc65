"""Static registration of the scans of one view, then isolation of the goal object (paper II-A).

``register_view(frames, config)`` is the one entry point. Two profiles share the back-projection, the
fusion and the isolation, and differ in how the scans are aligned:

- ``paper``: clouds in each camera's frame, no prior. Per pair: FPFH RANSAC, table removal, FPFH RANSAC
  again, then for voxel 5 mm and 2 mm colored ICP then GICP, then non-overlapping points are dropped and
  point-to-plane ICP runs at 1 mm. A pose graph of the scans gives the poses; scan 0's believed pose
  anchors the view in ``base``.
- ``default``: the arm's believed poses are the prior (right to ~2 mm and ~0.2 degrees). The clouds are
  cropped early to a region around where the first scan looks. Per pair: dense RGB-D odometry
  (photometric + depth) from the prior at half resolution; the result is checked (fitness, inlier RMSE,
  size of the correction); a pair that fails tries GICP from the prior, and only then global registration
  (FPFH RANSAC on the table-free clouds, refined, scored on the table-free clouds). Pose graph with the
  edges to scan 0 as the spanning tree and the others as prunable loop closures; same anchor.

Both then fuse PC_global at ``output_voxel``, fit the table (RANSAC + least squares, normal toward the
cameras), and keep the DBSCAN cluster that stands on the table nearest the first scan's centre pixel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from common.geometry import invert, transform_error, transform_points
from common.messages import RGBDFrame
from services.registration.blocks import overlap_only
from services.registration.cloud import (
    CloudError,
    FramePoints,
    downsample,
    estimate_normals,
    frame_points,
    from_o3d,
    to_o3d,
)

from . import pairwise as pw
from .config import StaticConfig
from .errors import BadFramesError, EmptyDepthError
from .isolate import footprint_centre, isolate_object
from .odometry import pinhole, rgbd_image, rgbd_odometry
from .posegraph import optimise
from .result import ScanResult, Stopwatch, ViewResult
from .table import segment_table

MIN_SCAN_POINTS = 500  # a scan with fewer valid depth points than this is treated as empty


@dataclass
class Scan:
    """One frame's points in its camera frame (cropped to the ROI later), with its believed pose."""

    index: int
    pts_cam: FramePoints
    T_believed: np.ndarray


# ----------------------------------------------------------------------------------------------- inputs


def _load_scans(frames: list[RGBDFrame], cfg: StaticConfig) -> list[Scan]:
    if not isinstance(frames, list | tuple) or len(frames) == 0:
        raise BadFramesError("register_view needs at least one RGBDFrame")
    scans = []
    for i, f in enumerate(frames):
        if not isinstance(f, RGBDFrame):
            raise BadFramesError(f"frame {i} is a {type(f).__name__}, not an RGBDFrame")
        try:
            pts = frame_points(f, depth_min=cfg.depth_min, depth_max=cfg.depth_max, edge_threshold=cfg.edge_threshold)
        except CloudError as exc:
            raise BadFramesError(f"frame {i}: {exc.message}", detail={"frame": i, **exc.detail}) from None
        if len(pts) < MIN_SCAN_POINTS:
            raise EmptyDepthError(
                f"frame {i} has no usable depth",
                detail={
                    "frame": i,
                    "valid_points": len(pts),
                    "depth_range_m": [cfg.depth_min, cfg.depth_max],
                },
            )
        scans.append(Scan(index=i, pts_cam=pts, T_believed=np.asarray(f.T_base_camera, dtype=np.float64)))
    sizes = {np.asarray(f.depth).shape for f in frames}
    if len(sizes) > 1:
        raise BadFramesError(
            "the scans of one view must come from one camera (image sizes differ)",
            detail={"sizes": sorted(list(s) for s in sizes)},
        )
    return scans


def centre_depth(frame: RGBDFrame, cfg: StaticConfig) -> float | None:
    """Median valid depth (m) in a window at the principal point: the paper's "centre depth"."""
    h, w = frame.depth.shape
    u, v = int(round(frame.intrinsics.cx)), int(round(frame.intrinsics.cy))
    for half in (cfg.centre_window // 2, cfg.centre_window * 2):
        win = frame.depth[max(0, v - half) : min(h, v + half + 1), max(0, u - half) : min(w, u + half + 1)]
        z = win.astype(np.float64).ravel() * frame.depth_scale
        z = z[(z >= cfg.depth_min) & (z <= cfg.depth_max)]
        if z.size:
            return float(np.median(z))
    return None


def _roi_mask(xyz_base: np.ndarray, seed: np.ndarray, cfg: StaticConfig) -> np.ndarray:
    """Points in the region of interest around the seed point.

    With a known up axis (``base``: table top at height 0 along it), a cylinder about that axis through the
    seed, from ``roi_below`` under the table to ``roi_above`` over it; without one, a sphere about the seed.
    """
    rel = xyz_base - seed
    if cfg.expected_up is None:
        return np.einsum("ij,ij->i", rel, rel) <= cfg.roi_radius**2
    up = np.asarray(cfg.expected_up, dtype=np.float64)
    up = up / np.linalg.norm(up)
    height = xyz_base @ up
    radial = rel - np.outer(rel @ up, up)
    return (
        (np.einsum("ij,ij->i", radial, radial) <= cfg.roi_radius**2)
        & (height >= -cfg.roi_below)
        & (height <= cfg.roi_above)
    )


# ------------------------------------------------------------------------------------- default profile


@dataclass
class PairOutcome:
    """One registered pair: T maps source camera points into the target camera's frame."""

    T: np.ndarray
    path: str  # "local" | "global"
    method: str  # "rgbd_odometry" | "icp" | "fpfh+icp"
    check: pw.PairResult
    verified: bool


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


def _gicp_pyramid(src: dict, tgt: dict, cfg: StaticConfig, init: np.ndarray) -> np.ndarray:
    T = init
    for k, v in enumerate(cfg.local_voxels):
        T = pw.icp_generalized(src["levels"][k], tgt["levels"][k], v * cfg.local_corr_factor, T, cfg.local_iterations).T
    return T


def _odometry(src: dict, tgt: dict, init: np.ndarray, cfg: StaticConfig) -> tuple[bool, np.ndarray]:
    return rgbd_odometry(
        src["image"](),
        tgt["image"](),
        src["intrinsic"],
        init,
        iterations=cfg.odometry_iterations,
        max_depth_diff=cfg.odometry_max_depth_diff,
        depth_min=cfg.depth_min,
        depth_max=cfg.depth_max,
        hybrid=cfg.odometry_hybrid,
    )


def _pair_default(src: dict, tgt: dict, prior: np.ndarray, cfg: StaticConfig, seed: int) -> PairOutcome:
    """Local first (RGB-D odometry, then GICP, both from the arm's prior), global only when both fail."""
    ok, T = _odometry(src, tgt, prior, cfg)
    res, passed = _check(src["check"], tgt["check"], T, prior, cfg)
    if ok and passed:
        return PairOutcome(T, "local", "rgbd_odometry", res, True)
    candidates = [PairOutcome(T, "local", "rgbd_odometry", res, False)] if ok else []
    _levels(src, cfg)
    _levels(tgt, cfg)
    T = _gicp_pyramid(src, tgt, cfg, prior)
    res, passed = _check(src["check"], tgt["check"], T, prior, cfg)
    if passed:
        return PairOutcome(T, "local", "icp", res, True)
    candidates.append(PairOutcome(T, "local", "icp", res, False))
    return _global_default(src, tgt, cfg, seed, candidates)


def _object_part(d: dict, cfg: StaticConfig, seed: int) -> None:
    """Table-free copies of a scan for the global fallback: the table makes false high-overlap matches."""
    if "obj_global" not in d:
        obj = _strip_table(d["pcd"], cfg, seed)
        d["obj_global"] = downsample(obj, cfg.global_object_voxel, toward=np.zeros(3))
        d["obj_check"] = downsample(obj, cfg.check_voxel, normals=False)


def _global_default(src: dict, tgt: dict, cfg: StaticConfig, seed: int, candidates: list[PairOutcome]) -> PairOutcome:
    """The arm's prior failed: FPFH RANSAC on the table-free clouds (a few seeds), each refined by GICP and
    polished by odometry; every candidate, the local ones too, is scored on the table-free clouds."""
    _object_part(src, cfg, seed)
    _object_part(tgt, cfg, seed + 1)
    corr = cfg.check_voxel * cfg.check_corr_factor
    scored = []
    for c in candidates:
        scored.append((pw.evaluate(src["obj_check"], tgt["obj_check"], c.T, corr), c))
    for k in range(cfg.global_attempts):
        glob = pw.global_ransac(
            src["obj_global"],
            tgt["obj_global"],
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
        check = pw.evaluate(src["check"], tgt["check"], T, corr)
        scored.append(
            (
                pw.evaluate(src["obj_check"], tgt["obj_check"], T, corr),
                PairOutcome(T, "global", "fpfh+icp", check, False),
            )
        )
    obj_res, best = max(scored, key=lambda sc: (round(sc[0].fitness, 2), -sc[0].rmse))
    best.verified = bool(
        obj_res.fitness >= cfg.min_fitness and best.check.fitness >= cfg.min_fitness and best.check.rmse <= cfg.max_rmse
    )
    return best


def _levels(d: dict, cfg: StaticConfig) -> None:
    if "levels" not in d:
        d["levels"] = [downsample(d["pcd"], v, toward=np.zeros(3)) for v in cfg.local_voxels]


def _register_default(
    scans: list[Scan], frames: list[RGBDFrame], seed_base: np.ndarray | None, cfg: StaticConfig, sw: Stopwatch
) -> tuple[list[np.ndarray], list[PairOutcome | None]]:
    """Camera poses relative to scan 0 (T_c0_cj), from the arm's poses refined pairwise."""
    with sw("roi"):
        for s in scans:
            if seed_base is not None and cfg.roi_radius is not None:
                keep = _roi_mask(transform_points(s.T_believed, s.pts_cam.xyz), seed_base, cfg)
                if keep.sum() >= MIN_SCAN_POINTS:
                    s.pts_cam = s.pts_cam.subset(keep)
    if len(scans) == 1:
        return [np.eye(4)], [None]
    with sw("preprocess"):
        data = []
        for s, f in zip(scans, frames, strict=True):
            pcd = to_o3d(s.pts_cam.xyz, s.pts_cam.rgb)
            data.append(
                {
                    "pcd": pcd,
                    "check": downsample(pcd, cfg.check_voxel, normals=False),
                    "image": _lazy(
                        lambda f=f: rgbd_image(
                            f, step=cfg.odometry_step, depth_min=cfg.depth_min, depth_max=cfg.depth_max
                        )
                    ),
                    "intrinsic": pinhole(f, cfg.odometry_step),
                }
            )
    with sw("register"):
        edges, outcomes = [], {}
        for j in range(1, len(scans)):
            for i in range(j) if cfg.use_pose_graph else (0,):
                prior = invert(scans[i].T_believed) @ scans[j].T_believed
                out = _pair_default(data[j], data[i], prior, cfg, cfg.seed + 31 * j + i)
                outcomes[(j, i)] = out
                if cfg.use_pose_graph:
                    corr = cfg.check_voxel * cfg.check_corr_factor
                    edges.append((j, i, out.T, pw.information(data[j]["check"], data[i]["check"], corr, out.T)))
    with sw("pose_graph"):
        initial = [np.eye(4)] + [outcomes[(j, 0)].T for j in range(1, len(scans))]
        poses = _optimise(len(scans), edges, initial, cfg)
    return poses, [None] + [outcomes[(j, 0)] for j in range(1, len(scans))]


def _optimise(n: int, edges: list, initial: list[np.ndarray], cfg: StaticConfig) -> list[np.ndarray]:
    if cfg.use_pose_graph and n > 2:
        return optimise(n, edges, initial, cfg.check_voxel * cfg.check_corr_factor)
    return initial


def _lazy(make):
    """A zero-argument callable that builds its value once, on first use."""
    box: list = []

    def get():
        if not box:
            box.append(make())
        return box[0]

    return get


# --------------------------------------------------------------------------------------- paper profile


def _strip_table(pcd: o3d.geometry.PointCloud, cfg: StaticConfig, seed: int) -> o3d.geometry.PointCloud:
    """Remove the largest RANSAC plane (the table) from a scan, as the paper does before re-registering."""
    coarse = pcd.voxel_down_sample(cfg.plane_voxel)
    if len(coarse.points) < 3:
        return pcd
    o3d.utility.random.seed(int(seed))
    model, _ = coarse.segment_plane(cfg.plane_distance, 3, cfg.plane_iterations)
    n = np.asarray(model[:3])
    dist = np.abs(np.asarray(pcd.points) @ n + model[3]) / np.linalg.norm(n)
    kept = pcd.select_by_index(np.flatnonzero(dist > cfg.plane_distance))
    return kept if len(kept.points) >= MIN_SCAN_POINTS else pcd


def _pair_paper(src: dict, tgt: dict, cfg: StaticConfig, seed: int) -> pw.PairResult:
    """Paper II-A pairwise registration (clouds in their camera frames, no prior)."""
    g = cfg.global_voxel
    kw = dict(
        iterations=cfg.ransac_iterations,
        confidence=cfg.ransac_confidence,
        radius_factor=cfg.fpfh_radius_factor,
        corr_factor=cfg.ransac_corr_factor,
    )
    first = pw.global_ransac(src["global"], tgt["global"], g, seed=seed, **kw)
    second = pw.global_ransac(src["global_notable"], tgt["global_notable"], g, seed=seed + 1, **kw)
    # keep the better of the two rounds, judged on the table-free clouds the refinement uses
    e1 = pw.evaluate(src["global_notable"], tgt["global_notable"], first.T, g * cfg.ransac_corr_factor)
    e2 = pw.evaluate(src["global_notable"], tgt["global_notable"], second.T, g * cfg.ransac_corr_factor)
    T = second.T if e2.fitness >= e1.fitness else first.T
    res = None
    for k, v in enumerate(cfg.paper_refine_voxels):
        s, t = src["levels"][k], tgt["levels"][k]
        max_corr = v * cfg.local_corr_factor
        T = pw.icp_colored(s, t, max_corr, T, cfg.local_iterations, cfg.color_lambda_geometric).T
        res = pw.icp_generalized(s, t, max_corr, T, cfg.local_iterations)
        T = res.T
    s_ov, t_ov = overlap_only(src["final"], tgt["final"], T)
    if len(s_ov.points) >= 3 * 10 and len(t_ov.points) >= 3 * 10:
        res = pw.icp_point_to_plane(s_ov, t_ov, cfg.paper_final_voxel * 2.0, T, cfg.local_iterations)
    return res


def _register_paper(
    scans: list[Scan], cfg: StaticConfig, sw: Stopwatch
) -> tuple[list[np.ndarray], list[PairOutcome | None]]:
    """Camera poses relative to scan 0 (T_c0_cj) from the paper's pairwise registration and pose graph."""
    if len(scans) == 1:
        return [np.eye(4)], [None]
    origin = np.zeros(3)
    with sw("preprocess"):
        data = []
        for s in scans:
            pcd = to_o3d(s.pts_cam.xyz, s.pts_cam.rgb)
            notable = _strip_table(pcd, cfg, cfg.seed + s.index)
            data.append(
                {
                    "global": downsample(pcd, cfg.global_voxel, toward=origin),
                    "global_notable": downsample(notable, cfg.global_voxel, toward=origin),
                    "levels": [downsample(notable, v, toward=origin) for v in cfg.paper_refine_voxels],
                    "final": downsample(notable, cfg.paper_final_voxel, toward=origin),
                }
            )
    n = len(scans)
    edges, outcomes = [], {}
    fine = cfg.paper_refine_voxels[-1] * cfg.local_corr_factor
    with sw("register"):
        for j in range(1, n):
            for i in range(j):
                res = _pair_paper(data[j], data[i], cfg, cfg.seed + 31 * j + i)
                check = pw.evaluate(data[j]["levels"][-1], data[i]["levels"][-1], res.T, fine)
                outcomes[(j, i)] = PairOutcome(res.T, "paper", "paper", check, check.fitness >= cfg.min_fitness)
                edges.append((j, i, res.T, pw.information(data[j]["levels"][-1], data[i]["levels"][-1], fine, res.T)))
    with sw("pose_graph"):
        initial = [np.eye(4)] + [outcomes[(j, 0)].T for j in range(1, n)]
        poses = optimise(n, edges, initial, fine) if cfg.use_pose_graph and n > 2 else initial
    return poses, [None] + [outcomes[(j, 0)] for j in range(1, n)]


# ------------------------------------------------------------------------------------------ entry point


def _scan_results(scans: list[Scan], poses: list[np.ndarray], outcomes: list[PairOutcome | None]) -> list[ScanResult]:
    """Per-scan figures; scan 0's believed pose anchors the view, the others follow T_c0_cj."""
    T0 = scans[0].T_believed
    out = []
    for s, P, oc in zip(scans, poses, outcomes, strict=True):
        if oc is None:
            out.append(
                ScanResult(
                    index=s.index,
                    T_base_camera=T0.copy(),
                    T_base_camera_believed=s.T_believed,
                    path="anchor",
                    method="anchor",
                    fitness=1.0,
                    inlier_rmse=0.0,
                    verified=True,
                    n_points=len(s.pts_cam),
                )
            )
        else:
            out.append(
                ScanResult(
                    index=s.index,
                    T_base_camera=T0 @ P,
                    T_base_camera_believed=s.T_believed,
                    path=oc.path,
                    method=oc.method,
                    fitness=oc.check.fitness,
                    inlier_rmse=oc.check.rmse,
                    verified=oc.verified,
                    n_points=len(s.pts_cam),
                )
            )
    return out


def register_view(frames: list[RGBDFrame], config: StaticConfig | None = None) -> ViewResult:
    """Register the scans of one view and isolate the goal object, all in ``base``.

    ``frames`` are the scans of one view (scan 0 first: its believed pose anchors the view and its image
    centre picks the object). Raises ``BadFramesError`` (unusable inputs), ``EmptyDepthError`` (a frame
    with no depth), ``NoTableError`` (no supporting plane, or not horizontal) or ``NoObjectError`` (nothing
    on the table near where the first scan looks).
    """
    cfg = config or StaticConfig()
    sw = Stopwatch()
    frames = list(frames) if isinstance(frames, list | tuple) else frames
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        with sw("backproject"):
            scans = _load_scans(frames, cfg)
            z0 = centre_depth(frames[0], cfg)
            # the paper's seed: the first scan's centre pixel (x = y = 0 in the optical frame) at its depth
            seed_base = None if z0 is None else transform_points(scans[0].T_believed, np.array([[0.0, 0.0, z0]]))[0]
        if cfg.profile == "paper":
            poses, outcomes = _register_paper(scans, cfg, sw)
        else:
            poses, outcomes = _register_default(scans, frames, seed_base, cfg, sw)
        scan_results = _scan_results(scans, poses, outcomes)
        with sw("fuse"):
            xyz = np.concatenate(
                [transform_points(r.T_base_camera, s.pts_cam.xyz) for r, s in zip(scan_results, scans, strict=True)]
            )
            rgb = np.concatenate([s.pts_cam.rgb for s in scans])
            viewpoint = np.mean([r.T_base_camera[:3, 3] for r in scan_results], axis=0)
            scene = to_o3d(xyz, rgb).voxel_down_sample(cfg.output_voxel)
            scene_xyz = np.asarray(scene.points)
        with sw("table"):
            up = None if cfg.expected_up is None else np.asarray(cfg.expected_up, dtype=np.float64)
            table = segment_table(
                scene_xyz,
                viewpoint=viewpoint,
                distance=cfg.plane_distance,
                iterations=cfg.plane_iterations,
                seed=cfg.seed,
                voxel=cfg.plane_voxel,
                min_fraction=cfg.min_table_fraction,
                min_points=cfg.min_table_points,
                expected_up=up,
                max_tilt_deg=cfg.max_table_tilt_deg,
                seed_point=seed_base,
                max_seed_height=cfg.max_object_height,
                expected_height=cfg.expected_table_height,
                height_tolerance=cfg.table_height_tolerance,
                max_planes=cfg.table_planes,
            )
        with sw("cluster"):
            T0 = scan_results[0].T_base_camera
            iso = isolate_object(
                scene_xyz,
                table.plane,
                seed_point=seed_base,
                ray_origin=T0[:3, 3],
                ray_dir=T0[:3, 2],
                clearance=cfg.table_clearance,
                max_height=cfg.max_object_height,
                cluster_voxel=cfg.cluster_voxel,
                eps=cfg.dbscan_eps,
                min_points=cfg.dbscan_min_points,
                min_object_points=cfg.min_object_points,
                select_by=cfg.select_by,
                max_support_gap=cfg.max_support_gap,
            )
        with sw("object"):
            obj = scene.select_by_index(np.flatnonzero(iso.mask))
            estimate_normals(obj, cfg.output_voxel * 2.5, toward=viewpoint)
            centre, height = footprint_centre(np.asarray(obj.points), table.plane)
            cloud = from_o3d(obj, frame="base")
    return ViewResult(
        object_cloud=cloud,
        table=table.plane,
        object_center=centre,
        object_height=height,
        scans=scan_results,
        timings=sw.total(),
        profile=cfg.profile,
        seed_point=seed_base,
        scene_points=len(scene_xyz),
        n_clusters=iso.n_clusters,
        figures={
            "table_fraction": round(table.fraction, 4),
            "selection_distance_m": round(iso.selection_distance, 5),
            "cluster_sizes": iso.cluster_sizes[:8],
        },
    )
