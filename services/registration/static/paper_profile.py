"""The ``paper`` profile's alignment (paper II-A): clouds in each camera's frame, no prior.

Per pair: FPFH RANSAC, table removal, FPFH RANSAC again, then for voxel 5 mm and 2 mm colored ICP then
GICP, then non-overlapping points are dropped and point-to-plane ICP runs at 1 mm. A pose graph of all the
pairs gives the poses. See docs/static-registration.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from services.registration.blocks import overlap_only
from services.registration.cloud import downsample, to_o3d

from . import pairwise as pw
from .config import StaticConfig
from .posegraph import optimise
from .result import PairOutcome, Stopwatch
from .scans import Scan, strip_table


@dataclass
class PaperScan:
    """One scan's clouds for the paper's pair registration, all in its camera frame."""

    whole: o3d.geometry.PointCloud  # ``global_voxel``, table included (first RANSAC round)
    notable: o3d.geometry.PointCloud  # ``global_voxel``, table removed (second round)
    levels: list[o3d.geometry.PointCloud]  # table removed, one per ``paper_refine_voxels``
    final: o3d.geometry.PointCloud  # table removed, ``paper_final_voxel`` (overlap-only ICP)


def _prepare(scan: Scan, cfg: StaticConfig) -> PaperScan:
    origin = np.zeros(3)
    pcd = to_o3d(scan.pts_cam.xyz, scan.pts_cam.rgb)
    notable = strip_table(pcd, cfg, cfg.seed + scan.index)
    return PaperScan(
        whole=downsample(pcd, cfg.global_voxel, toward=origin),
        notable=downsample(notable, cfg.global_voxel, toward=origin),
        levels=[downsample(notable, v, toward=origin) for v in cfg.paper_refine_voxels],
        final=downsample(notable, cfg.paper_final_voxel, toward=origin),
    )


def register_pair(src: PaperScan, tgt: PaperScan, cfg: StaticConfig, seed: int) -> pw.PairResult:
    """Paper II-A pairwise registration (clouds in their camera frames, no prior)."""
    g = cfg.global_voxel
    kw = dict(
        iterations=cfg.ransac_iterations,
        confidence=cfg.ransac_confidence,
        radius_factor=cfg.fpfh_radius_factor,
        corr_factor=cfg.ransac_corr_factor,
    )
    first = pw.global_ransac(src.whole, tgt.whole, g, seed=seed, **kw)
    second = pw.global_ransac(src.notable, tgt.notable, g, seed=seed + 1, **kw)
    # keep the better of the two rounds, judged on the table-free clouds the refinement uses
    e1 = pw.evaluate(src.notable, tgt.notable, first.T, g * cfg.ransac_corr_factor)
    e2 = pw.evaluate(src.notable, tgt.notable, second.T, g * cfg.ransac_corr_factor)
    T = second.T if e2.fitness >= e1.fitness else first.T
    res = None
    for k, v in enumerate(cfg.paper_refine_voxels):
        s, t = src.levels[k], tgt.levels[k]
        max_corr = v * cfg.local_corr_factor
        T = pw.icp_colored(s, t, max_corr, T, cfg.local_iterations, cfg.color_lambda_geometric).T
        res = pw.icp_generalized(s, t, max_corr, T, cfg.local_iterations)
        T = res.T
    s_ov, t_ov = overlap_only(src.final, tgt.final, T)
    if len(s_ov.points) >= 3 * 10 and len(t_ov.points) >= 3 * 10:
        res = pw.icp_point_to_plane(s_ov, t_ov, cfg.paper_final_voxel * 2.0, T, cfg.local_iterations)
    return res


def register(scans: list[Scan], cfg: StaticConfig, sw: Stopwatch) -> tuple[list[np.ndarray], list[PairOutcome | None]]:
    """Camera poses relative to scan 0 (T_c0_cj) from the paper's pairwise registration and pose graph."""
    if len(scans) == 1:
        return [np.eye(4)], [None]
    with sw("preprocess"):
        data = [_prepare(s, cfg) for s in scans]
    n = len(scans)
    edges, outcomes = [], {}
    fine = cfg.paper_refine_voxels[-1] * cfg.local_corr_factor
    with sw("register"):
        for j in range(1, n):
            for i in range(j):
                res = register_pair(data[j], data[i], cfg, cfg.seed + 31 * j + i)
                check = pw.evaluate(data[j].levels[-1], data[i].levels[-1], res.T, fine)
                outcomes[(j, i)] = PairOutcome(res.T, "paper", "paper", check, check.fitness >= cfg.min_fitness)
                edges.append((j, i, res.T, pw.information(data[j].levels[-1], data[i].levels[-1], fine, res.T)))
    with sw("pose_graph"):
        initial = [np.eye(4)] + [outcomes[(j, 0)].T for j in range(1, n)]
        poses = optimise(n, edges, initial, fine) if cfg.use_pose_graph and n > 2 else initial
    return poses, [None] + [outcomes[(j, 0)] for j in range(1, n)]
