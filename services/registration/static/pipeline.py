"""Static registration of the scans of one view, then isolation of the goal object (paper II-A).

``register_view(frames, config)`` is the one entry point: the flow both profiles share (back-projection
and seed in ``scans``, fusion, table, isolation, per-scan results). How the scans are aligned is each
profile's own module: ``paper_profile`` (the paper's prior-free pair registration and pose graph) and
``default_profile`` (the arm's poses as the prior, RGB-D odometry, checked, with fallbacks).

Both then fuse the verified scans into PC_global at ``output_voxel`` (a scan that failed its check is left
out, and the view says why), fit the table (RANSAC + least squares, normal toward the cameras), and keep the DBSCAN
cluster that stands on the table nearest the first scan's centre pixel.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

from common.geometry import transform_points
from common.messages import RGBDFrame
from common.open3d_threads import limit_open3d_threads
from services.registration.cloud import estimate_normals, from_o3d, to_o3d

from . import default_profile, paper_profile
from .config import StaticConfig
from .isolate import footprint_centre, isolate_object
from .result import PairOutcome, ScanResult, StaticViewResult, Stopwatch
from .scans import Scan, centre_depth, load_scans
from .table import segment_table

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
            why = None if oc.verified else (oc.reason or f"unverified: fitness {oc.check.fitness:.2f}")
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
                    fused=oc.verified,
                    rejected=why,
                )
            )
    return out


def register_view(frames: list[RGBDFrame], config: StaticConfig | None = None) -> StaticViewResult:
    """Register the scans of one view and isolate the goal object, all in ``base``.

    ``frames`` are the scans of one view (scan 0 first: its believed pose anchors the view and its image
    centre picks the object). Raises ``BadFramesError`` (unusable inputs), ``EmptyDepthError`` (a frame
    with no depth), ``NoTableError`` (no supporting plane, or not horizontal) or ``NoObjectError`` (nothing
    on the table near where the first scan looks).
    """
    cfg = config or StaticConfig()
    # Open3D's parallel reductions (odometry, ICP) add partial sums in thread-finishing order: bound its threads
    # to the project's one knob (OMP_NUM_THREADS, 1 when unset) so the same scans give the same poses in any
    # caller (the services do it at start; ``reconstruct``, ``import`` and library users get it here)
    limit_open3d_threads()
    sw = Stopwatch()
    frames = list(frames) if isinstance(frames, list | tuple) else frames
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        with sw("backproject"):
            scans = load_scans(frames, cfg)
            z0 = centre_depth(frames[0], cfg)
            # the paper's seed: the first scan's centre pixel (x = y = 0 in the optical frame) at its depth
            seed_base = None if z0 is None else transform_points(scans[0].T_believed, np.array([[0.0, 0.0, z0]]))[0]
        if cfg.profile == "paper":
            poses, outcomes = paper_profile.register(scans, cfg, sw)
        else:
            poses, outcomes = default_profile.register(scans, frames, seed_base, cfg, sw)
        scan_results = _scan_results(scans, poses, outcomes)
        with sw("fuse"):
            # a scan that failed its check, or whose correction the arm cannot explain, is never fused: scan 0
            # (the anchor) always is, so a view left with scan 0 alone is still a view
            fused = [(r, s) for r, s in zip(scan_results, scans, strict=True) if r.fused]
            xyz = np.concatenate([transform_points(r.T_base_camera, s.pts_cam.xyz) for r, s in fused])
            rgb = np.concatenate([s.pts_cam.rgb for _, s in fused])
            viewpoint = np.mean([r.T_base_camera[:3, 3] for r, _ in fused], axis=0)
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
            # the surface the object stands on: the table, or a turntable's / platform's top above it
            stands_on = iso.support if iso.support is not None else table.plane
            centre, height = footprint_centre(np.asarray(obj.points), stands_on)
            cloud = from_o3d(obj, frame="base")
    return StaticViewResult(
        object_cloud=cloud,
        table=stands_on,
        object_center=centre,
        object_height=height,
        scans=scan_results,
        timings=sw.total(),
        cpu_timings=sw.cpu_total(),
        profile=cfg.profile,
        seed_point=seed_base,
        scene_points=len(scene_xyz),
        n_clusters=iso.n_clusters,
        figures={
            "table_fraction": round(table.fraction, 4),
            "support_height_m": None if iso.support is None else round(table.plane.offset - iso.support.offset, 4),
            "selection_distance_m": round(iso.selection_distance, 5),
            "cluster_sizes": iso.cluster_sizes[:8],
        },
    )
