"""Evaluate a reconstructed model against ground truth: alignment, Chamfer distance and F-score.

The paper (III, "To get the Chamfer distance we align the entire reconstruction with the ground truth model
from the HOPE dataset and take the average distance between the closest points") reports a Chamfer distance
after aligning the model to the ground-truth mesh. It does not say how it aligns; we do what is standard and
reproducible: an initial alignment (the caller's ``init_T`` if it has one, e.g. the true object pose in the
simulator, else centroid + principal-axes candidates) followed by point-to-point ICP at decreasing
correspondence distances, keeping the candidate with the lowest symmetric Chamfer distance.

Definitions (all distances are closest-point distances, reported in millimetres):
- accuracy     = mean over model points of the distance to the ground truth (model -> GT),
- completeness = mean over GT points of the distance to the model (GT -> model),
- chamfer      = (accuracy + completeness) / 2, the mean closest-point distance in both directions,
- precision@t  = fraction of model points within t of the GT, recall@t = fraction of GT points within t of
  the model, F@t = 2PR / (P + R) (Knapitsch et al., Tanks and Temples), for t = 2 mm and 5 mm.

Ground truth may be an (N, 3) array of points or an ``open3d.geometry.TriangleMesh``; a mesh is sampled
uniformly (seeded) into ``n_gt_samples`` points and model -> GT distances are then exact point-to-triangle
distances (Open3D ``RaycastingScene``), so the accuracy figure is not inflated by the sampling density.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from services.registration.cloud import o3d_seeded, to_o3d
from services.registration.dynamic.fourpcs_common import as_xyz, check_transform

F_SCORE_THRESHOLDS_M = (0.002, 0.005)


@dataclass(frozen=True)
class AlignConfig:
    """Model-to-GT alignment: every candidate gets the coarse ICP stages on a small subsample, the best one
    the fine stages on a larger one (correspondence distances in m, coarse to fine)."""

    coarse_correspondence_m: tuple[float, ...] = (0.02, 0.01)
    fine_correspondence_m: tuple[float, ...] = (0.005, 0.002)
    iterations_per_stage: int = 30
    coarse_points: int = 3000
    fine_points: int = 20000  # model points; the GT subsample is twice this


def point_errors(query_xyz: np.ndarray, reference: np.ndarray | o3d.geometry.TriangleMesh,
                 *, workers: int = -1) -> np.ndarray:
    """Distance (m) from every query point to the closest point of ``reference`` (points or mesh).

    This is the per-point error a colored error map is drawn from (model points vs ground truth).
    """
    query = as_xyz(query_xyz, "query_xyz")
    if isinstance(reference, o3d.geometry.TriangleMesh):
        return _mesh_distances(query, reference)
    ref = as_xyz(reference, "reference")
    dist, _ = cKDTree(ref).query(query, k=1, workers=workers)
    return dist


def chamfer_metrics(model_xyz: np.ndarray, gt_points: np.ndarray, *,
                    gt_mesh: o3d.geometry.TriangleMesh | None = None, workers: int = -1) -> dict:
    """Chamfer, accuracy, completeness, precision/recall/F-score of already aligned clouds (no alignment).

    Returns figures in millimetres (``*_mm``) and fractions (``precision_2mm``, ``fscore_5mm``, ...).
    """
    model = as_xyz(model_xyz, "model_xyz")
    gt = as_xyz(gt_points, "gt_points")
    d_model = _mesh_distances(model, gt_mesh) if gt_mesh is not None else \
        cKDTree(gt).query(model, k=1, workers=workers)[0]
    d_gt = cKDTree(model).query(gt, k=1, workers=workers)[0]
    accuracy = float(d_model.mean())
    completeness = float(d_gt.mean())
    out = {
        "chamfer_mm": 1000.0 * 0.5 * (accuracy + completeness),
        "accuracy_mm": 1000.0 * accuracy,
        "completeness_mm": 1000.0 * completeness,
        "n_model_points": int(model.shape[0]),
        "n_gt_points": int(gt.shape[0]),
    }
    for tau in F_SCORE_THRESHOLDS_M:
        tag = f"{round(tau * 1000)}mm"
        precision = float(np.mean(d_model < tau))
        recall = float(np.mean(d_gt < tau))
        out[f"precision_{tag}"] = precision
        out[f"recall_{tag}"] = recall
        denom = precision + recall
        out[f"fscore_{tag}"] = 0.0 if denom == 0 else 2 * precision * recall / denom
    return out


def evaluate_model(model_xyz: np.ndarray, gt_points: np.ndarray | o3d.geometry.TriangleMesh, *,
                   align: bool = True, init_T: np.ndarray | None = None, n_gt_samples: int = 100_000,
                   config: AlignConfig | None = None, seed: int = 0) -> dict:
    """Align ``model_xyz`` to the ground truth (optional) and measure it; see the module doc for definitions.

    Returns the ``chamfer_metrics`` keys plus ``T_gt_model`` (4x4 list, maps model points onto the GT) and
    ``aligned`` (whether ICP alignment ran). With ``align=False`` the model is measured where it is, after
    ``init_T`` if one is given.
    """
    model = as_xyz(model_xyz, "model_xyz", min_points=3)
    gt_mesh = gt_points if isinstance(gt_points, o3d.geometry.TriangleMesh) else None
    gt = sample_mesh(gt_mesh, n_gt_samples, seed=seed) if gt_mesh is not None else \
        as_xyz(gt_points, "gt_points", min_points=3)
    T0 = np.eye(4) if init_T is None else check_transform(init_T, "init_T")
    T = align_to_ground_truth(model, gt, init_T=init_T, config=config, seed=seed) if align else T0
    aligned_model = model @ T[:3, :3].T + T[:3, 3]
    out = chamfer_metrics(aligned_model, gt, gt_mesh=gt_mesh)
    out["T_gt_model"] = T.tolist()
    out["aligned"] = bool(align)
    return out


def align_to_ground_truth(model_xyz: np.ndarray, gt_xyz: np.ndarray, *, init_T: np.ndarray | None = None,
                          config: AlignConfig | None = None, seed: int = 0) -> np.ndarray:
    """Rigid transform mapping the model onto the GT: best of several initial guesses refined by ICP.

    Candidates are ``init_T`` (if given) and, always, the centroid match with the model's principal axes
    rotated onto the GT's (the 4 proper sign choices) - enough for objects whose pose is unknown but whose
    shape is recovered. Each gets the coarse ICP stages on a small subsample; the one with the smallest
    symmetric Chamfer there gets the fine stages on a larger subsample.
    """
    cfg = config or AlignConfig()
    model = as_xyz(model_xyz, "model_xyz", min_points=3)
    gt = as_xyz(gt_xyz, "gt_xyz", min_points=3)
    rng = np.random.default_rng(seed)
    candidates = [] if init_T is None else [check_transform(init_T, "init_T")]
    candidates += _principal_axes_candidates(model, gt)
    m_small, g_small = _subsample(model, cfg.coarse_points, rng), _subsample(gt, 2 * cfg.coarse_points, rng)
    src, tgt = to_o3d(m_small), to_o3d(g_small)
    g_tree = cKDTree(g_small)
    best_T, best_score = np.eye(4), np.inf
    for T0 in candidates:
        T = _icp_stages(src, tgt, T0, cfg.coarse_correspondence_m, cfg.iterations_per_stage)
        moved = m_small @ T[:3, :3].T + T[:3, 3]
        score = g_tree.query(moved)[0].mean() + cKDTree(moved).query(g_small)[0].mean()
        if score < best_score:
            best_T, best_score = T, score
    src = to_o3d(_subsample(model, cfg.fine_points, rng))
    tgt = to_o3d(_subsample(gt, 2 * cfg.fine_points, rng))
    return _icp_stages(src, tgt, best_T, cfg.fine_correspondence_m, cfg.iterations_per_stage)


def _icp_stages(src: o3d.geometry.PointCloud, tgt: o3d.geometry.PointCloud, T: np.ndarray,
                distances: tuple[float, ...], iterations: int) -> np.ndarray:
    for dist in distances:
        T = o3d.pipelines.registration.registration_icp(
            src, tgt, dist, T, o3d.pipelines.registration.TransformationEstimationPointToPoint(),
            o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=iterations),
        ).transformation
    return np.array(T)


def _subsample(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    return points if points.shape[0] <= n else points[rng.choice(points.shape[0], n, replace=False)]


def sample_mesh(mesh: o3d.geometry.TriangleMesh, n: int, *, seed: int = 0) -> np.ndarray:
    """``n`` points sampled uniformly by area on a mesh, reproducibly (Open3D's sampler is seeded)."""
    with o3d_seeded(seed):
        return np.asarray(mesh.sample_points_uniformly(number_of_points=int(n)).points, dtype=np.float64)


def _principal_axes_candidates(model: np.ndarray, gt: np.ndarray) -> list[np.ndarray]:
    """Transforms putting the model's centroid on the GT's and its principal axes on the GT's axes."""
    cm, cg = model.mean(axis=0), gt.mean(axis=0)
    _, Vm = np.linalg.eigh(np.cov((model - cm).T))
    _, Vg = np.linalg.eigh(np.cov((gt - cg).T))
    out = []
    for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
        Vm_s = Vm.copy()
        Vm_s[:, 0] *= sx
        Vm_s[:, 1] *= sy
        Vm_s[:, 2] = np.cross(Vm_s[:, 0], Vm_s[:, 1])
        Vg_r = Vg.copy()
        Vg_r[:, 2] = np.cross(Vg_r[:, 0], Vg_r[:, 1])
        R = Vg_r @ Vm_s.T
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = cg - R @ cm
        out.append(T)
    return out


def _mesh_distances(points: np.ndarray, mesh: o3d.geometry.TriangleMesh) -> np.ndarray:
    """Exact unsigned point-to-triangle distances via Open3D's ray-casting scene (CPU)."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    query = o3d.core.Tensor(points.astype(np.float32))
    return scene.compute_distance(query).numpy().astype(np.float64)


def view_agreement(posed_views: list[np.ndarray], *, near: float = 0.010, close: float = 0.003) -> list[dict]:
    """Self-consistency of a model without ground truth: how well each view agrees with the others.

    For view k (points already posed in the model frame), the points that have a point of *another* view
    within ``near`` are the ones the others also saw; the agreement is the share of those within ``close``.
    A misplaced view has its overlap ``near`` but not ``close`` and scores low. Returns, per view,
    ``{"view", "points", "overlapping", "agreement"}`` (agreement None when nothing overlaps).
    """
    out = []
    trees = [cKDTree(np.asarray(v, dtype=np.float64)) for v in posed_views]
    for k, pts in enumerate(posed_views):
        pts = np.asarray(pts, dtype=np.float64)
        d = np.full(len(pts), np.inf)
        for j, tree in enumerate(trees):
            if j != k and len(pts):
                dj, _ = tree.query(pts, k=1, distance_upper_bound=near)
                d = np.minimum(d, dj)
        overlapping = int(np.sum(d <= near))
        agree = float(np.sum(d <= close)) / overlapping if overlapping else None
        out.append({"view": k, "points": int(len(pts)), "overlapping": overlapping, "agreement": agree})
    return out
