"""Figures of an export against the simulator's ground truth (evaluation only, simulated sessions).

The mesh and the point model are measured by the one evaluator (``services/registration/evaluation``) the
acquisition reports its accuracy with, as the acquisition calls it: 60,000 true surface samples posed where
the object stood in view 0 (``T_base_object_true`` of the first scan), ICP-aligned from there, Chamfer
distance in millimetres. The
mesh is sampled uniformly by area into as many points as the point model has, so both are compared at the
same density.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import open3d as o3d

from common.errors import ObjscanError
from services.export.inputs import SessionModel
from services.registration.api import evaluate_model, sample_mesh

#: True surface samples, as many as the acquisition's own evaluation draws.
GT_POINTS = 60000


def true_surface(model: SessionModel, n: int = GT_POINTS) -> tuple[np.ndarray, float] | None:
    """True surface samples posed in ``base`` at view 0 and the true volume (m^3), or None outside the simulator.

    Points, as the acquisition's own evaluation uses (``gt_points`` of the twin, 60,000 of them).
    """
    import trimesh

    from services.sim.catalogue import load_object
    from services.sim.ground_truth import posed_surface

    T = model.ground_truth_pose()
    name = model.data.get("object")
    if T is None or not name:
        return None
    try:
        obj = load_object(str(name))
    except ObjscanError:
        return None
    pts = posed_surface(obj, T, n)
    volume = abs(float(trimesh.Trimesh(obj.vertices, obj.triangles, process=False).volume))
    return pts, volume


def ground_truth_figures(model: SessionModel, mesh_object: o3d.geometry.TriangleMesh, T_model_object: np.ndarray,
                         mesh_volume: float, seed: int = 0) -> dict[str, Any] | None:
    """``mesh_chamfer_mm``, ``points_chamfer_mm``, ``volume_ratio`` (+ details), or None without ground truth."""
    truth = true_surface(model)
    if truth is None:
        return None
    gt, gt_volume = truth
    posed = o3d.geometry.TriangleMesh(mesh_object)
    posed.transform(T_model_object)
    samples = sample_mesh(posed, len(model.xyz), seed=seed)
    points = evaluate_model(model.xyz, gt, align=True, init_T=np.eye(4), seed=seed)
    meshed = evaluate_model(samples, gt, align=True, init_T=np.eye(4), seed=seed)
    keys = ("chamfer_mm", "accuracy_mm", "completeness_mm", "fscore_2mm", "fscore_5mm")
    return {"mesh_chamfer_mm": meshed["chamfer_mm"], "points_chamfer_mm": points["chamfer_mm"],
            "volume_ratio": mesh_volume / gt_volume if gt_volume > 0 else None,
            "true_volume_m3": gt_volume,
            "mesh": {k: meshed[k] for k in keys}, "points": {k: points[k] for k in keys}}
