"""``bench real`` judges a model on the views it kept.

A model that set a pair aside (a registration that flipped a face) or left a view out is posed without
them: its loop is measured over the views it kept, as posed, and a view it left out is not counted in the
agreement. Two kept neighbours that share nothing leave the loop unmeasured, never closed.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import open3d as o3d

from bench.real import judge, model_figures

STEP_DEG = 45.0
VIEWS = 8


def _rot_z(deg: float) -> np.ndarray:
    T = np.eye(4)
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    T[:2, :2] = [[c, -s], [s, c]]
    return T


def _surface() -> tuple[np.ndarray, np.ndarray]:
    """Points and outward normals of a wavy column's side (radius 5 cm +- 1.2 cm, 6 cm high), ~2 mm apart:
    its bumps pin every turn, so exact poses are where ICP stays."""
    t = np.radians(np.arange(0.0, 360.0, 2.0))
    r = 0.05 + 0.008 * np.sin(5 * t) + 0.004 * np.sin(3 * t + 1.0)
    dr = 0.04 * np.cos(5 * t) + 0.012 * np.cos(3 * t + 1.0)
    z = np.arange(0.0, 0.06, 0.002)
    ring = np.stack([r * np.cos(t), r * np.sin(t)], axis=-1)
    tangent = np.stack([dr * np.cos(t) - r * np.sin(t), dr * np.sin(t) + r * np.cos(t)], axis=-1)
    normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=-1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    xyz = np.concatenate([np.column_stack([ring, np.full(len(t), h)]) for h in z])
    nrm = np.concatenate([np.column_stack([normal, np.zeros(len(t))]) for _ in z])
    return xyz, nrm


def _model(folder: Path, left_out: list[int], misplaced: dict[int, float] | None = None) -> dict:
    """A model folder of eight side views a 45-degree turn apart, each seeing +-45 degrees of the surface,
    posed exactly (``misplaced``: view -> degrees its pose is off), whose pair loop composes a flipped pair
    the model set aside (90 degrees)."""
    xyz, nrm = _surface()
    (folder / "views").mkdir(parents=True)
    poses = []
    for k in range(VIEWS):
        towards = _rot_z(k * STEP_DEG)[:3, :3] @ np.array([1.0, 0.0, 0.0])
        seen = xyz[nrm @ towards > np.cos(np.radians(45.0))]
        T_model_view = _rot_z(k * STEP_DEG)
        in_view = (seen - T_model_view[:3, 3]) @ T_model_view[:3, :3]  # the view's own frame
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(in_view))
        o3d.io.write_point_cloud(str(folder / "views" / f"view_{k:02d}.ply"), pcd)
        poses.append(_rot_z((misplaced or {}).get(k, 0.0)) @ T_model_view)
    model = {"views_used": list(range(VIEWS)), "T_model_view": [P.tolist() for P in poses],
             "views_left_out": left_out,
             "outlier_views": {"implausible_edges": [{"edge": 3, "source_view": 3, "target_view": 2,
                                                      "correction_deg": 90.0, "window_deg": 30.0}]},
             "loop_closure": {"rotation_deg": 90.0, "translation_mm": 60.0},
             "edges": [{"path": "prior"}] * VIEWS, "configuration": "no_region",
             "consistency": {"min_posed_fitness": 0.6}, "points": 1000}
    (folder / "report.json").write_text(json.dumps({"model": model}))
    return model


def _row(model: dict, folder: Path) -> dict:
    row = {"import_status": "closed", "accepted": True, **model_figures(model, folder)}
    row["status"], row["reason"] = judge(row)
    return row


def test_a_model_that_set_a_flipped_pair_aside_is_judged_on_the_loop_it_kept(tmp_path):
    row = _row(_model(tmp_path, []), tmp_path)
    assert row["loop_over"] == "kept views" and row["all_pairs_deg"] == 90.0
    assert row["loop_deg"] < 0.5 and row["loop_translation_mm"] < 1.0
    assert row["status"] == "closed", row["reason"]


def test_a_view_the_model_left_out_is_not_judged_with_the_others(tmp_path):
    """View 3 left out and posed 20 degrees off: the agreement is the kept views'; its neighbours 2 and 4
    share nothing (90 degrees apart), so the loop over the kept views is not measured, and not closed."""
    row = _row(_model(tmp_path / "off", [3], misplaced={3: 20.0}), tmp_path / "off")
    in_place = _row(_model(tmp_path / "in_place", [3]), tmp_path / "in_place")
    assert len(row["agreement_per_view"]) == VIEWS - 1
    assert row["agreement_per_view"] == in_place["agreement_per_view"]  # where view 3 sits changes nothing
    assert row["loop_deg"] is None and [(g["from"], g["to"]) for g in row["gaps"]] == [(2, 4)]
    assert row["status"] == "missed" and "not measured" in row["reason"] and "2 -> 4" in row["reason"]


def test_a_model_that_kept_every_pair_reports_its_own_loop(tmp_path):
    model = _model(tmp_path, [])
    model["outlier_views"] = {"implausible_edges": []}
    model["loop_closure"] = {"rotation_deg": 0.4, "translation_mm": 1.2}
    row = _row(model, tmp_path)
    assert row["loop_over"] == "pairs" and row["loop_deg"] == 0.4 and row["loop_translation_mm"] == 1.2
