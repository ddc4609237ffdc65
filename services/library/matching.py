"""``find``: which stored models best explain a partial view of an object.

Two stages, as the issue asks (the paper's stated next step toward recognising objects):

1. **Descriptor shortlist.** GOOD of the query against the GOOD of each model's synthetic partial views
   (``descriptors.py``); the ``shortlist`` closest models go on. Cheap: no point cloud is loaded.
2. **Registration fitness.** Each shortlisted model is registered with the query: FPFH + RANSAC (Open3D,
   seeded) and, when both clouds are upright (``upright``: z up, as every session model and view in
   ``base`` is), also yaw hypotheses about the model's vertical axis through its centroid; each start is
   refined by ICP (colored ICP when both clouds have colors) and the best kept. A model is scored on
   what it explains:

   - ``fitness``: fraction of query points within ``inlier_distance`` of the model (the view fits on it);
   - ``coverage``: fraction of the model points a camera looking from the query's side would see that lie
     within ``inlier_distance`` of the query (the model is not much bigger than what was seen). The camera
     direction is model centroid -> query centroid: a partial view lies on the side it was seen from;
   - ``color``: agreement of chromaticity (r, g, b / (r + g + b), so lighting does not matter) between
     query points and their nearest model points, ``exp(-mean difference / color_sigma)``; 1 without colors.

   ``score = geometric mean of (fitness, coverage) * color``. Shapes alone cannot tell apart the HOPE
   milk and orange juice cartons (same carton) or the soup and sauce cans; their prints can.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from common.messages import PointCloud
from services.library.descriptors import DescriptorConfig, check_xyz, describe, view_distance
from services.library.errors import BadModelInput
from services.registration.api import (
    ColorICPConfig,
    FeatureMatchConfig,
    chromaticity,
    colored_icp,
    fpfh_features,
    ransac_feature_match,
    to_o3d,
)


class ModelSource(Protocol):
    """What matching reads from a library (``store.ModelLibrary`` is one): the entries, each entry's cloud
    and stored descriptors. A protocol rather than the class, so the store can offer ``find`` without the two
    modules importing each other."""

    descriptor_config: DescriptorConfig

    def list(self) -> list: ...

    def load_cloud(self, entry_id: str) -> o3d.geometry.PointCloud: ...

    def descriptors(self, entry_id: str) -> dict[str, np.ndarray]: ...

reg = o3d.pipelines.registration


@dataclass(frozen=True)
class FindConfig:
    """Knobs of ``find``; defaults suit table-top objects of 5-25 cm scanned at ~0.4 m."""

    shortlist: int = 3
    voxel: float = 0.004
    inlier_distance: float = 0.006
    upright: bool = True
    yaw_steps: int = 16  # 22.5 deg apart: at 45 deg a can's colour ICP basin (about its yaw) can miss every start
    ransac_trials: int = 1
    features: FeatureMatchConfig = FeatureMatchConfig()  # FPFH at 5 voxels, RANSAC's iterations
    icp_iterations: int = 30
    color_sigma: float = 0.1
    min_points: int = 50
    seed: int = 0


@dataclass
class Match:
    """One ranked answer: the model id, its score in [0, 1] (higher is better) and how it was reached."""

    id: str
    score: float
    detail: dict[str, Any]

    def __iter__(self):  # so ``for id, score, detail in matches`` works, as the issue spells the result
        return iter((self.id, self.score, self.detail))


@dataclass
class _Prepared:
    pcd: o3d.geometry.PointCloud
    fpfh: Any
    xyz: np.ndarray
    chroma: np.ndarray | None
    tree: cKDTree


def find(library: ModelSource, cloud: np.ndarray | PointCloud | str | Path, top_k: int = 3, *,
         rgb: np.ndarray | None = None, config: FindConfig | None = None) -> list[Match]:
    """Rank the library's models for a partial view ``cloud``; returns up to ``top_k`` ``Match``es, best first.

    ``cloud`` is an (N, 3) array (``rgb`` (N, 3) uint8 optional), a wire ``PointCloud`` or a point-cloud
    file. Models outside the shortlist are not returned. An empty library gives ``[]``.
    """
    cfg = config or FindConfig()
    if int(top_k) < 1:
        raise BadModelInput("top_k must be at least 1", code="bad_value", detail={"top_k": top_k})
    xyz, colors = _query_arrays(cloud, rgb)
    entries = library.list()
    if not entries:
        return []
    cache: dict[tuple[int, ...], np.ndarray] = {}
    ranked = sorted(((_descriptor_distance(library, xyz, e.id, cache), e) for e in entries), key=lambda t: t[0])
    query = _prepare(xyz, colors, cfg)
    out = []
    for rank, (dist, entry) in enumerate(ranked[:max(cfg.shortlist, 1)]):
        model_pcd = library.load_cloud(entry.id)
        model = _prepare(np.asarray(model_pcd.points),
                         (np.asarray(model_pcd.colors) * 255.0) if model_pcd.has_colors() else None, cfg)
        figures = register_and_score(query, model, cfg)
        figures.update({"descriptor_distance": round(dist, 5), "descriptor_rank": rank + 1,
                        "object": entry.metadata.object_name})
        out.append(Match(entry.id, figures.pop("score"), figures))
    out.sort(key=lambda m: -m.score)
    return out[:int(top_k)]


def _descriptor_distance(library: ModelSource, xyz: np.ndarray, entry_id: str,
                         cache: dict[tuple[int, ...], np.ndarray]) -> float:
    """GOOD distance of the query to a model's synthetic views, at the resolutions that model was stored
    with (a library opened with another ``DescriptorConfig`` still compares like with like)."""
    stored = library.descriptors(entry_id)
    cfg = replace(library.descriptor_config, n_bins=tuple(int(n) for n in np.atleast_1d(stored["n_bins"])))
    if cfg.n_bins not in cache:
        cache[cfg.n_bins] = describe(xyz, cfg)
    return view_distance(cache[cfg.n_bins], stored["views"], cfg)


def _query_arrays(cloud: np.ndarray | PointCloud | str | Path, rgb: np.ndarray | None
                  ) -> tuple[np.ndarray, np.ndarray | None]:
    if isinstance(cloud, str | Path):
        p = Path(cloud)
        if not p.is_file():
            raise BadModelInput(f"{p} does not exist", code="io_error", detail={"path": str(p)})
        pcd = o3d.io.read_point_cloud(str(p))
        xyz = np.asarray(pcd.points)
        rgb = np.asarray(pcd.colors) * 255.0 if pcd.has_colors() else None
    elif isinstance(cloud, PointCloud):
        xyz, rgb = cloud.xyz, cloud.rgb
    else:
        xyz = cloud
    xyz = check_xyz(xyz, "query cloud")
    if rgb is not None:
        rgb = np.asarray(rgb, dtype=np.float64)
        if rgb.shape != xyz.shape or not np.isfinite(rgb).all():
            raise BadModelInput("rgb must be finite and (N, 3) like the points",
                                detail={"rgb": list(rgb.shape), "xyz": list(xyz.shape)})
    return xyz, rgb


def _prepare(xyz: np.ndarray, rgb: np.ndarray | None, cfg: FindConfig) -> _Prepared:
    pcd = to_o3d(xyz, None if rgb is None else np.clip(rgb, 0.0, 255.0)).voxel_down_sample(cfg.voxel)
    if len(pcd.points) < cfg.min_points:
        raise BadModelInput(f"cloud has only {len(pcd.points)} points at voxel {cfg.voxel} m",
                            code="too_few_points", detail={"points": len(pcd.points)})
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2.5 * cfg.voxel, max_nn=30))
    fpfh = fpfh_features(pcd, cfg.voxel, cfg.features)
    pts = np.asarray(pcd.points)
    chroma = chromaticity(255.0 * np.asarray(pcd.colors)) if pcd.has_colors() else None
    return _Prepared(pcd, fpfh, pts, chroma, cKDTree(pts))


def _starts(query: _Prepared, model: _Prepared, cfg: FindConfig) -> list[np.ndarray]:
    """Initial poses (query -> model): RANSAC results, and yaw hypotheses when both are upright."""
    out = []
    for trial in range(cfg.ransac_trials):
        res = ransac_feature_match(query.pcd, model.pcd, query.fpfh, model.fpfh, 1.5 * cfg.inlier_distance,
                                   seed=cfg.seed + trial, config=cfg.features)
        out.append(np.array(res.transformation))
    if cfg.upright:
        # put the query's centroid where it would be on the model: same height, pushed out from the model's
        # axis by the query's own offset from its side (a front view lies off the object's centre)
        cq, cm = query.xyz.mean(axis=0), model.xyz.mean(axis=0)
        for k in range(cfg.yaw_steps):
            a = 2.0 * np.pi * k / cfg.yaw_steps
            R = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
            T = np.eye(4)
            T[:3, :3] = R
            T[:3, 3] = cm - R @ cq
            out.append(T)
    return out


def _refine(query: _Prepared, model: _Prepared, T: np.ndarray, cfg: FindConfig) -> np.ndarray:
    crit = reg.ICPConvergenceCriteria(max_iteration=cfg.icp_iterations)
    for dist in (3.0 * cfg.inlier_distance, cfg.inlier_distance):
        T = reg.registration_icp(query.pcd, model.pcd, dist, T, reg.TransformationEstimationPointToPlane(),
                                 crit).transformation
    if query.chroma is not None and model.chroma is not None:
        # a failed colour ICP (too few correspondences) keeps the geometric result
        T = colored_icp(query.pcd, model.pcd, cfg.inlier_distance, T,
                        ColorICPConfig(max_iteration=cfg.icp_iterations)).T
    return np.array(T)


def _score(query: _Prepared, model: _Prepared, T: np.ndarray, cfg: FindConfig) -> dict[str, float]:
    moved = query.xyz @ T[:3, :3].T + T[:3, 3]
    d_q, nn = model.tree.query(moved, k=1, distance_upper_bound=cfg.inlier_distance)
    inlier = np.isfinite(d_q)
    fitness = float(inlier.mean())
    # model points visible from the query's side
    cm = model.xyz.mean(axis=0)
    direction = moved.mean(axis=0) - cm
    norm = float(np.linalg.norm(direction))
    diameter = float(np.linalg.norm(model.xyz.max(axis=0) - model.xyz.min(axis=0)))
    direction = direction / norm if norm > 1e-6 else np.array([0.0, 0.0, 1.0])
    _, vis = model.pcd.hidden_point_removal(cm + 3.0 * diameter * direction, 300.0 * diameter)
    vis = np.asarray(vis)
    d_m, _ = cKDTree(moved).query(model.xyz[vis], k=1, distance_upper_bound=cfg.inlier_distance)
    coverage = float(np.isfinite(d_m).mean()) if vis.size else 0.0
    color = 1.0
    color_diff = None
    if query.chroma is not None and model.chroma is not None and inlier.any():
        color_diff = float(np.abs(query.chroma[inlier] - model.chroma[nn[inlier]]).sum(axis=1).mean())
        color = float(np.exp(-color_diff / cfg.color_sigma))
    rmse = float(np.sqrt(np.mean(d_q[inlier] ** 2))) if inlier.any() else float("inf")
    score = float(np.sqrt(fitness * coverage) * color)
    return {"score": score, "fitness": fitness, "coverage": coverage, "color": color,
            "color_difference": color_diff, "inlier_rmse_mm": 1000.0 * rmse}


def register_and_score(query: _Prepared, model: _Prepared, cfg: FindConfig) -> dict[str, Any]:
    """Best of the refined starts by score; returns the figures and the transform (query -> model)."""
    best: dict[str, Any] | None = None
    for T0 in _starts(query, model, cfg):
        T = _refine(query, model, T0, cfg)
        figures = _score(query, model, T, cfg)
        if best is None or figures["score"] > best["score"]:
            best = figures | {"T_model_query": T.round(6).tolist()}
    assert best is not None
    return {k: (round(v, 5) if isinstance(v, float) else v) for k, v in best.items()} | {
        "starts": cfg.ransac_trials + (cfg.yaw_steps if cfg.upright else 0)}

