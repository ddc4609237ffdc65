"""The loop of a model over the views it kept, for ``objscan bench real``.

Why: the model's own ``loop_closure`` composes every pair transform around the loop, including a pair the
model set aside (a registration that flipped a face, beyond what a turn error can be) and the pairs of a view
it left out. Such a model is posed without them, so their composition says nothing about it: a castard
folder with frames missing composed a 90-degree flipped pair into a 97-degree "loop" while every pair the
model kept agreed with it. When the model set something aside, the loop is measured again on what it kept:
each kept view against the next kept view round the loop, both as posed in the model, refined by
point-to-plane ICP; the refinements composed are the loop. Two kept neighbours that share too little to be
registered (a gap a left-out view or missing frames opened) leave the loop unchecked: only the full-turn
constraint placed them, and the loop is then reported as not measured, never as closed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import open3d as o3d

from common.geometry import rotation_angle_deg

reg = o3d.pipelines.registration

VOXEL = 0.002  # m, the clouds compared (the bench's agreement works at the same voxel)
ICP_DISTANCES = (0.008, 0.004, 0.002)  # m, coarse to fine (as the model re-registers a disagreeing view)
OVERLAP_DISTANCE = 0.010  # m: a point of one view with a point of the other this close is in their overlap
MIN_OVERLAP = 0.25  # the least overlap that can vouch for a pair (the model's ``min_posed_overlap``)


def kept_views(model: dict[str, Any]) -> list[int]:
    """The views the model fused, in loop order."""
    left = set(model.get("views_left_out") or [])
    return [k for k in model["views_used"] if k not in left]


def set_aside(model: dict[str, Any]) -> dict[str, Any]:
    """What the model kept out of its poses: pair edges judged implausible and views left out."""
    edges = (model.get("outlier_views") or {}).get("implausible_edges", [])
    return {"edges": [{"from": e["source_view"], "to": e["target_view"]} for e in edges],
            "views": list(model.get("views_left_out") or [])}


def posed_clouds(model: dict[str, Any], views_dir: Path, views: list[int]) -> dict[int, o3d.geometry.PointCloud]:
    """Each view's cloud (``views_dir/view_KK.ply``) posed in the model frame, with normals."""
    poses = {k: np.asarray(T, dtype=float) for k, T in zip(model["views_used"], model["T_model_view"], strict=True)}
    out = {}
    for k in views:
        pcd = o3d.io.read_point_cloud(str(views_dir / f"view_{k:02d}.ply")).voxel_down_sample(VOXEL)
        pcd.transform(poses[k])
        pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=4 * VOXEL, max_nn=30))
        out[k] = pcd
    return out


def overlap(source: o3d.geometry.PointCloud, target: o3d.geometry.PointCloud) -> float:
    """The share of ``source``'s points with a point of ``target`` within ``OVERLAP_DISTANCE``, as posed."""
    return float(reg.evaluate_registration(source, target, OVERLAP_DISTANCE, np.eye(4)).fitness)


def refine(source: o3d.geometry.PointCloud, target: o3d.geometry.PointCloud) -> tuple[np.ndarray, float]:
    """The correction ICP still makes to ``source`` posed on ``target``, and their overlap at the result."""
    T = np.eye(4)
    for d in ICP_DISTANCES:
        r = reg.registration_icp(source, target, d, T, reg.TransformationEstimationPointToPlane(),
                                 reg.ICPConvergenceCriteria(relative_fitness=1e-6, relative_rmse=1e-6,
                                                            max_iteration=40))
        if np.isfinite(r.transformation).all():
            T = np.asarray(r.transformation)
    return T, overlap(o3d.geometry.PointCloud(source).transform(T), target)


def loop_over_kept(clouds: dict[int, o3d.geometry.PointCloud], order: list[int]) -> dict[str, Any]:
    """The loop over ``order`` (kept views, loop order), measured on the posed ``clouds`` (see the module doc).

    ``rotation_deg`` / ``translation_mm`` (at the centre of the kept views) are None when a step cannot be
    measured; ``steps`` gives each step's correction and overlap, ``gaps`` the steps too thin to measure.
    """
    L, steps, gaps = np.eye(4), [], []
    centre = np.mean([np.asarray(clouds[k].get_center()) for k in order], axis=0)
    for a, b in zip(order, order[1:] + order[:1], strict=True):
        shared = overlap(clouds[b], clouds[a])
        if shared < MIN_OVERLAP:  # nothing to register on: ICP from here would slide anywhere
            step = {"from": a, "to": b, "correction_deg": None, "overlap": round(shared, 3)}
            steps.append(step)
            gaps.append(step)
            continue
        T, after = refine(clouds[b], clouds[a])
        step = {"from": a, "to": b, "correction_deg": round(rotation_angle_deg(T[:3, :3]), 3),
                "overlap": round(shared, 3), "overlap_refined": round(after, 3)}
        steps.append(step)
        if after < MIN_OVERLAP:
            gaps.append(step)
        L = T @ L
    if gaps:
        return {"rotation_deg": None, "translation_mm": None, "steps": steps, "gaps": gaps}
    return {"rotation_deg": rotation_angle_deg(L[:3, :3]),
            "translation_mm": 1000.0 * float(np.linalg.norm(L[:3, :3] @ centre + L[:3, 3] - centre)),
            "steps": steps, "gaps": []}


def model_loop(model: dict[str, Any], views_dir: Path) -> dict[str, Any]:
    """The model's loop as the bench reports it: its own pair composition when it kept every pair and view,
    else the loop over the views it kept (``loop_over_kept``), with what was set aside."""
    aside = set_aside(model)
    if not aside["edges"] and not aside["views"]:
        lc = model["loop_closure"]
        return {"rotation_deg": lc["rotation_deg"], "translation_mm": lc["translation_mm"], "over": "pairs"}
    order = kept_views(model)
    out = loop_over_kept(posed_clouds(model, views_dir, order), order)
    return {**out, "over": "kept views", "set_aside": aside,
            "all_pairs_deg": model["loop_closure"]["rotation_deg"]}
