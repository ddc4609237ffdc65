"""Static registration of the scans of one view, then isolation of the goal object (paper II-A).

``register_view(frames, config)`` is the one entry point. Two profiles share the back-projection, the
fusion and the isolation, and differ in how the scans are aligned:

- ``paper``: clouds in each camera's frame, no prior. Per pair: FPFH RANSAC, table removal, FPFH RANSAC
  again, then for voxel 5 mm and 2 mm colored ICP then GICP, then non-overlapping points are dropped and
  point-to-plane ICP runs at 1 mm. A pose graph of the scans gives the poses; scan 0's believed pose
  anchors the view in ``base``.
- ``default``: clouds in ``base`` through the arm's believed poses (already right to a few mm), cropped
  early to a region around where the first scan looks; per pair a coarse-to-fine ICP from those poses,
  checked (fitness, RMSE, size of the correction); only a pair that fails the check runs FPFH RANSAC, and
  the better-checked of the two wins. Same pose graph and anchor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from common.geometry import invert, transform_error, transform_points
from common.messages import RGBDFrame
from services.registration.cloud import (
    CloudError,
    FramePoints,
    downsample,
    estimate_normals,
    frame_points,
    to_o3d,
)

from . import pairwise as pw
from .config import StaticConfig
from .errors import BadFramesError, EmptyDepthError, NoObjectError
from .isolate import footprint_centre, isolate_object
from .posegraph import optimise
from .result import ScanResult, Stopwatch, ViewResult
from .table import segment_table

MIN_SCAN_POINTS = 500  # a scan with fewer valid depth points than this is treated as empty


@dataclass
class Scan:
    """One frame's points in its camera frame, with its believed pose and camera centre."""

    index: int
    pts_cam: FramePoints
    T_believed: np.ndarray

    @property
    def camera_centre(self) -> np.ndarray:
        return self.T_believed[:3, 3]


# ----------------------------------------------------------------------------------------------- inputs


def _load_scans(frames: list[RGBDFrame], cfg: StaticConfig) -> list[Scan]:
    if not isinstance(frames, list | tuple) or len(frames) == 0:
        raise BadFramesError("register_view needs at least one RGBDFrame")
    scans = []
    for i, f in enumerate(frames):
        if not isinstance(f, RGBDFrame):
            raise BadFramesError(f"frame {i} is a {type(f).__name__}, not an RGBDFrame")
        try:
            pts = frame_points(f, depth_min=cfg.depth_min, depth_max=cfg.depth_max)
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


def _pyramid(pcd: o3d.geometry.PointCloud, voxels: tuple[float, ...], toward: np.ndarray) -> list:
    return [downsample(pcd, v, toward=toward) for v in voxels]


def _local(src_levels: list, tgt_levels: list, cfg: StaticConfig, init: np.ndarray) -> pw.PairResult:
    """Coarse-to-fine ICP: point-to-plane at each coarse level, colored ICP at the finest (if enabled)."""
    T = init
    res = None
    for k, v in enumerate(cfg.local_voxels):
        max_corr = v * cfg.local_corr_factor
        finest = k == len(cfg.local_voxels) - 1
        s, t = src_levels[k], tgt_levels[k]
        if finest and cfg.use_color and s.has_colors() and t.has_colors():
            res = pw.icp_colored(s, t, max_corr, T, cfg.local_iterations, cfg.color_lambda_geometric)
        else:
            res = pw.icp_point_to_plane(s, t, max_corr, T, cfg.local_iterations)
        T = res.T
    return res


def _passes(res: pw.PairResult, cfg: StaticConfig, prior: np.ndarray) -> bool:
    """The check a local result must pass: overlap, residual, and a correction the arm's error can explain."""
    dt, dr = transform_error(res.T, prior)
    return (
        res.fitness >= cfg.min_fitness
        and res.rmse <= cfg.max_rmse
        and dt <= cfg.max_correction_m
        and dr <= cfg.max_correction_deg
    )


def _pair_default(src: dict, tgt: dict, cfg: StaticConfig, seed: int) -> tuple[pw.PairResult, str, bool]:
    """Register one pair in ``base``: local first, global only if the local result fails the check."""
    eye = np.eye(4)
    local = _local(src["levels"], tgt["levels"], cfg, eye)
    if _passes(local, cfg, eye):
        return local, "local", True
    glob = pw.global_ransac(
        src["global"],
        tgt["global"],
        cfg.global_voxel,
        seed=seed,
        iterations=cfg.ransac_iterations,
        confidence=cfg.ransac_confidence,
        radius_factor=cfg.fpfh_radius_factor,
        corr_factor=cfg.ransac_corr_factor,
    )
    refined = _local(src["levels"], tgt["levels"], cfg, glob.T)
    glob_ok = refined.fitness >= cfg.min_fitness and refined.rmse <= cfg.max_rmse
    local_ok = local.fitness >= cfg.min_fitness and local.rmse <= cfg.max_rmse
    if glob_ok and (not local_ok or refined.fitness > local.fitness + 0.02):
        return refined, "global", True
    return local, "local", local_ok


def _register_default(
    scans: list[Scan], seed_base: np.ndarray | None, cfg: StaticConfig, sw: Stopwatch
) -> tuple[list[np.ndarray], list[ScanResult], list[np.ndarray]]:
    """Corrections C_j (base -> base, C_0 = I) such that C_j @ T_believed_j is scan j's pose."""
    with sw("roi"):
        base_pts = []
        for s in scans:
            xyz = transform_points(s.T_believed, s.pts_cam.xyz)
            if seed_base is not None and cfg.roi_radius is not None:
                keep = _roi_mask(xyz, seed_base, cfg)
                if keep.sum() >= MIN_SCAN_POINTS:
                    xyz, s.pts_cam = xyz[keep], s.pts_cam.subset(keep)
            base_pts.append(xyz)
    if len(scans) == 1:
        return [np.eye(4)], [_anchor_result(scans[0])], base_pts
    with sw("preprocess"):
        data = []
        for s, xyz in zip(scans, base_pts, strict=True):
            pcd = to_o3d(xyz, s.pts_cam.rgb)
            levels = _pyramid(pcd, cfg.local_voxels, s.camera_centre)
            data.append({"levels": levels, "_pcd": pcd, "centre": s.camera_centre})
    with sw("register"):
        edges, results = _all_pairs(scans, data, cfg)
    return _finish(scans, data, edges, results, cfg, sw, base_pts, path_of=None)


def _global_features(d: dict, cfg: StaticConfig) -> None:
    if "global" not in d:
        d["global"] = downsample(d["_pcd"], cfg.global_voxel, toward=d["centre"])


def _all_pairs(scans: list[Scan], data: list[dict], cfg: StaticConfig) -> tuple[list, dict]:
    edges, results = [], {}
    n = len(scans)
    for j in range(1, n):
        for i in range(j):
            src, tgt = data[j], data[i]
            _global_features(src, cfg)  # cheap at 1 cm; needed only when a pair falls back
            _global_features(tgt, cfg)
            res, path, ok = _pair_default(src, tgt, cfg, cfg.seed + 31 * j + i)
            results[(j, i)] = (res, path, ok)
            fine = cfg.local_voxels[-1] * cfg.local_corr_factor
            info = pw.information(src["levels"][-1], tgt["levels"][-1], fine, res.T)
            edges.append((j, i, res.T, info))
    return edges, results


def _finish(scans, data, edges, results, cfg, sw, base_pts, path_of):
    n = len(scans)
    initial = [np.eye(4)] + [results[(j, 0)][0].T for j in range(1, n)]
    with sw("pose_graph"):
        if cfg.use_pose_graph and n > 2:
            poses = optimise(n, edges, initial, cfg.local_voxels[-1] * cfg.local_corr_factor)
        else:
            poses = initial
    out = [_anchor_result(scans[0])]
    fine = cfg.local_voxels[-1] * cfg.local_corr_factor
    for j in range(1, n):
        ev = pw.evaluate(data[j]["levels"][-1], data[0]["levels"][-1], poses[j], fine)
        res, path, ok = results[(j, 0)]
        out.append(
            ScanResult(
                index=j,
                T_base_camera=poses[j] @ scans[j].T_believed,
                T_base_camera_believed=scans[j].T_believed,
                path=path_of or path,
                fitness=ev.fitness,
                inlier_rmse=ev.rmse,
                verified=ok,
                n_points=len(base_pts[j]),
            )
        )
    return poses, out, base_pts


def _anchor_result(scan: Scan) -> ScanResult:
    return ScanResult(
        index=scan.index,
        T_base_camera=scan.T_believed.copy(),
        T_base_camera_believed=scan.T_believed,
        path="anchor",
        fitness=1.0,
        inlier_rmse=0.0,
        verified=True,
        n_points=len(scan.pts_cam),
    )


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
    s_ov, t_ov = pw.overlap_only(src["final"], tgt["final"], T)
    if len(s_ov.points) >= 3 * 10 and len(t_ov.points) >= 3 * 10:
        res = pw.icp_point_to_plane(s_ov, t_ov, cfg.paper_final_voxel * 2.0, T, cfg.local_iterations)
    return res


def _register_paper(
    scans: list[Scan], cfg: StaticConfig, sw: Stopwatch
) -> tuple[list[np.ndarray], list[ScanResult], list[np.ndarray]]:
    """Corrections C_j in base from camera-frame pairwise registration anchored on scan 0's believed pose."""
    base_pts = [transform_points(s.T_believed, s.pts_cam.xyz) for s in scans]
    if len(scans) == 1:
        return [np.eye(4)], [_anchor_result(scans[0])], base_pts
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
                    "levels": _pyramid(notable, cfg.paper_refine_voxels, origin),
                    "final": downsample(notable, cfg.paper_final_voxel, toward=origin),
                }
            )
    n = len(scans)
    edges, rel = [], {}
    with sw("register"):
        for j in range(1, n):
            for i in range(j):
                res = _pair_paper(data[j], data[i], cfg, cfg.seed + 31 * j + i)
                fine = cfg.paper_refine_voxels[-1] * cfg.local_corr_factor
                info = pw.information(data[j]["levels"][-1], data[i]["levels"][-1], fine, res.T)
                edges.append((j, i, res.T, info))
                rel[(j, i)] = res
    with sw("pose_graph"):
        initial = [np.eye(4)] + [rel[(j, 0)].T for j in range(1, n)]
        fine = cfg.paper_refine_voxels[-1] * cfg.local_corr_factor
        cam_poses = optimise(n, edges, initial, fine) if cfg.use_pose_graph and n > 2 else initial
    # T_base_cj = T_base_c0(believed) @ T_c0_cj  ->  correction in base C_j = T_base_cj @ inv(T_believed_j)
    T0 = scans[0].T_believed
    corrections = [np.eye(4)] + [T0 @ cam_poses[j] @ invert(scans[j].T_believed) for j in range(1, n)]
    out = [_anchor_result(scans[0])]
    for j in range(1, n):
        ev = pw.evaluate(data[j]["levels"][-1], data[0]["levels"][-1], cam_poses[j], fine)
        out.append(
            ScanResult(
                index=j,
                T_base_camera=corrections[j] @ scans[j].T_believed,
                T_base_camera_believed=scans[j].T_believed,
                path="paper",
                fitness=ev.fitness,
                inlier_rmse=ev.rmse,
                verified=ev.fitness >= cfg.min_fitness,
                n_points=len(base_pts[j]),
            )
        )
    return corrections, out, base_pts


# ------------------------------------------------------------------------------------------ entry point


def register_view(frames: list[RGBDFrame], config: StaticConfig | None = None) -> ViewResult:
    """Register the scans of one view and isolate the goal object, all in ``base``.

    Raises ``BadFramesError`` (unusable inputs), ``EmptyDepthError`` (a frame with no depth),
    ``NoTableError`` (no horizontal supporting plane) or ``NoObjectError`` (nothing on the table near where
    the first scan looks).
    """
    cfg = config or StaticConfig()
    sw = Stopwatch()
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        with sw("backproject"):
            scans = _load_scans(list(frames) if isinstance(frames, tuple) else frames, cfg)
            z0 = centre_depth(frames[0], cfg)
            seed_cam = None if z0 is None else np.array([0.0, 0.0, z0])
            # the principal ray: x = y = 0 in the optical frame
            seed_base = None if seed_cam is None else transform_points(scans[0].T_believed, seed_cam[None])[0]
        if cfg.profile == "paper":
            corrections, scan_results, base_pts = _register_paper(scans, cfg, sw)
        else:
            corrections, scan_results, base_pts = _register_default(scans, seed_base, cfg, sw)
        with sw("fuse"):
            xyz = np.concatenate([transform_points(C, p) for C, p in zip(corrections, base_pts, strict=True)])
            rgb = np.concatenate([s.pts_cam.rgb for s in scans])
            centres = np.array([r.T_base_camera[:3, 3] for r in scan_results])
            viewpoint = centres.mean(axis=0)
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
            )
        with sw("object"):
            obj = scene.select_by_index(np.flatnonzero(iso.mask))
            if len(obj.points) == 0:
                raise NoObjectError("the selected cluster is empty")
            estimate_normals(obj, cfg.output_voxel * 2.5, toward=viewpoint)
            obj_xyz = np.asarray(obj.points)
            centre, height = footprint_centre(obj_xyz, table.plane)
            from services.registration.cloud import from_o3d

            cloud = from_o3d(obj, frame="base")
    timings = sw.total()
    return ViewResult(
        object_cloud=cloud,
        table=table.plane,
        object_center=centre,
        object_height=height,
        scans=scan_results,
        timings=timings,
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
