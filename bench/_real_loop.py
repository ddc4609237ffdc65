"""The loop of a model over the views it kept, for ``objscan bench real``.

Why: the model's own ``loop_closure`` composes every pair transform around the loop, including a pair the
model set aside (a registration that flipped a face, beyond what a turn error can be) and the pairs of a view
it left out. Such a model is posed without them, so their composition says nothing about it: a castard
folder with frames missing composed a 90-degree flipped pair into a 97-degree "loop" while every pair the
model kept agreed with it. When the model set something aside, the loop is measured again on what it kept:
each kept view against the next kept view round the loop. Where a pair the model kept links the two (its
registration not set aside; for a view the model re-registered, that re-registration), the pair's own
transform is the step, as in the model's ``loop_closure``; only where none does is the step measured anew, by
point-to-plane ICP of the two views as posed in the model. Why not ICP everywhere: on a box's large steps
(38 degrees, half the views shared) ICP from the posed views slides along the flat faces by degrees and
opens a loop the model's own pairs do not. The steps are composed exactly (in loop order, so the poses
cancel). Two kept neighbours with no kept pair that share too little to be registered (a gap a left-out view
or missing frames opened) leave the loop unchecked: only the full-turn constraint placed them, and the loop
is then reported as not measured, never as closed.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import open3d as o3d

from common.geometry import rotation_angle_deg
from services.registration.api import prerotation, stacking_frame, view_center

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


def stacked_poses(model: dict[str, Any], views: list[dict[str, Any]]) -> dict[int, np.ndarray]:
    """Each view's pose in the frame the model's pairs were registered in (the views stacked: each turned back
    by its commanded turn about view 0's table normal), from ``T_model_view`` and the reconstruct report's
    per-view entries (``views``: centre, table, height, commanded turn), by the stage's own ``prerotation``."""
    def view(v: dict[str, Any]) -> SimpleNamespace:  # what prerotation and stacking_frame read of a view
        normal = np.asarray(v["table"]["normal"], dtype=float)
        return SimpleNamespace(center=view_center(np.asarray(v["object_center"]), normal, v["object_height_m"]),
                               table=SimpleNamespace(normal=normal), commanded_turn_deg=v["commanded_turn_deg"])

    by_index = {int(v["index"]): view(v) for v in views}
    ref_center, axis = stacking_frame(by_index[model["views_used"][0]])
    return {k: np.asarray(T, dtype=float) @ np.linalg.inv(prerotation(by_index[k], ref_center, axis))
            for k, T in zip(model["views_used"], model["T_model_view"], strict=True)}


def kept_pairs(model: dict[str, Any], stacked: dict[int, np.ndarray]) -> dict[tuple[int, int], np.ndarray]:
    """The registrations the model kept, as ``(target, source) -> T`` (T maps the stacked source view onto the
    stacked target; ``stacked`` from ``stacked_poses``).

    A pair edge counts unless it was set aside or touches a view left out or re-registered; a re-registered
    view is posed by its re-registration onto one neighbour (the attempt the model chose), which is then that
    step's registration: the pose itself, so the step adds nothing the model did not measure."""
    outliers = model.get("outlier_views") or {}
    aside = {e["edge"] for e in outliers.get("implausible_edges", [])}
    moved = {r["view"] for r in outliers.get("reregistered", [])} | set(model.get("views_left_out") or [])
    out = {}
    for e in model["edges"]:
        if "T" not in e or e.get("index") in aside or e.get("path") == "failed":
            continue
        s, t = e["source_view"], e["target_view"]
        if s not in moved and t not in moved:
            out[(t, s)] = np.asarray(e["T"], dtype=float)
    for r in outliers.get("reregistered", []):
        chosen = [t["from_view"] for t in r.get("tried", []) if t["fitness"] == r.get("fitness")]
        k = r["view"]
        if chosen and chosen[0] in stacked and k in stacked:
            out[(chosen[0], k)] = np.linalg.inv(stacked[chosen[0]]) @ stacked[k]
    return out


def loop_over_kept(clouds: dict[int, o3d.geometry.PointCloud], order: list[int],
                   pairs: dict[tuple[int, int], np.ndarray] | None = None,
                   stacked: dict[int, np.ndarray] | None = None) -> dict[str, Any]:
    """The loop over ``order`` (kept views, loop order), measured on the posed ``clouds`` (see the module doc):
    a step between two views a kept pair links (``pairs``, with the views' ``stacked`` poses) is that pair's
    transform, any other step the ICP correction of the later view posed on the earlier.

    ``rotation_deg`` / ``translation_mm`` (at the centre of the kept views) are None when a step cannot be
    measured; ``steps`` gives each step's correction, how it was measured (``by``: pair or icp) and the
    views' overlap as posed, ``gaps`` the steps too thin to measure.
    """
    pairs, stacked = pairs or {}, stacked or {}
    L, steps, gaps = np.eye(4), [], []
    centre = np.mean([np.asarray(clouds[k].get_center()) for k in order], axis=0)
    for a, b in zip(order, order[1:] + order[:1], strict=True):
        shared = overlap(clouds[b], clouds[a])
        pair = pairs.get((a, b))
        if pair is None and (b, a) in pairs:
            pair = np.linalg.inv(pairs[(b, a)])
        if pair is not None and a in stacked and b in stacked:
            # the pair's step in the model frame: where it puts view b, as posed, relative to where b is posed
            T = stacked[a] @ pair @ np.linalg.inv(stacked[b])
            steps.append({"from": a, "to": b, "by": "pair", "correction_deg": round(rotation_angle_deg(T[:3, :3]), 3),
                          "overlap": round(shared, 3)})
            L = L @ T
            continue
        if shared < MIN_OVERLAP:  # nothing to register on: ICP from here would slide anywhere
            step = {"from": a, "to": b, "by": "icp", "correction_deg": None, "overlap": round(shared, 3)}
            steps.append(step)
            gaps.append(step)
            continue
        T, after = refine(clouds[b], clouds[a])
        step = {"from": a, "to": b, "by": "icp", "correction_deg": round(rotation_angle_deg(T[:3, :3]), 3),
                "overlap": round(shared, 3), "overlap_refined": round(after, 3)}
        steps.append(step)
        if after < MIN_OVERLAP:
            gaps.append(step)
        # right-multiplied, in loop order: each step's relation between the views' own frames is
        # P_a^-1 T P_b, and the poses cancel round the loop (the product is the loop, conjugated by P_first)
        L = L @ T
    if gaps:
        return {"rotation_deg": None, "translation_mm": None, "steps": steps, "gaps": gaps}
    return {"rotation_deg": rotation_angle_deg(L[:3, :3]),
            "translation_mm": 1000.0 * float(np.linalg.norm(L[:3, :3] @ centre + L[:3, 3] - centre)),
            "steps": steps, "gaps": []}


def model_loop(model: dict[str, Any], views_dir: Path, views: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """The model's loop as the bench reports it: its own pair composition when it kept every pair and view,
    else the loop over the views it kept (``loop_over_kept``: its kept pairs where they link two neighbours,
    when the reconstruct report's per-view entries ``views`` give the stacked frame), with what was set aside."""
    aside = set_aside(model)
    if not aside["edges"] and not aside["views"]:
        lc = model["loop_closure"]
        return {"rotation_deg": lc["rotation_deg"], "translation_mm": lc["translation_mm"], "over": "pairs"}
    order = kept_views(model)
    stacked = stacked_poses(model, views) if views else {}
    pairs = kept_pairs(model, stacked) if views else {}
    out = loop_over_kept(posed_clouds(model, views_dir, order), order, pairs, stacked)
    return {**out, "over": "kept views", "set_aside": aside,
            "all_pairs_deg": model["loop_closure"]["rotation_deg"]}
