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
import pytest

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


def _model(folder: Path, left_out: list[int], misplaced: dict[int, float] | None = None,
           pair_error_deg: float = 0.0, reregistered: dict | None = None) -> dict:
    """A model folder of eight side views a 45-degree turn apart, each seeing +-45 degrees of the surface,
    posed exactly (``misplaced``: view -> degrees its pose is off), whose pair loop composes a flipped pair
    the model set aside (90 degrees). Each pair kept turns ``pair_error_deg`` more than the poses say;
    ``reregistered``: the model's record of a view it re-registered."""
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
    # the pairs map the stacked source (each view turned back by its commanded turn) onto the stacked target
    edges = [{"index": k, "source_view": (k + 1) % VIEWS, "target_view": k, "path": "prior",
              "T": _rot_z(90.0 if k == 2 else pair_error_deg).tolist()} for k in range(VIEWS)]
    edges[-1].update(source_view=0, target_view=VIEWS - 1)
    model = {"views_used": list(range(VIEWS)), "T_model_view": [P.tolist() for P in poses],
             "views_left_out": left_out,
             "outlier_views": {"implausible_edges": [{"edge": 2, "source_view": 3, "target_view": 2,
                                                      "correction_deg": 90.0, "window_deg": 30.0}],
                               "reregistered": [reregistered] if reregistered else []},
             "loop_closure": {"rotation_deg": 90.0, "translation_mm": 60.0},
             "edges": edges, "configuration": "no_region",
             "consistency": {"min_posed_fitness": 0.6}, "points": 1000}
    # the object turned clockwise as the views go (the camera stands still): commanded turns -45 deg a view
    views = [{"index": k, "commanded_turn_deg": -k * STEP_DEG, "object_center": [0.0, 0.0, -0.03],
              "object_height_m": 0.06, "table": {"normal": [0.0, 0.0, 1.0]}} for k in range(VIEWS)]
    (folder / "report.json").write_text(json.dumps({"model": model, "views": views}))
    return model


def _row(model: dict, folder: Path) -> dict:
    views = json.loads((folder / "report.json").read_text())["views"]
    row = {"import_status": "closed", "accepted": True, **model_figures(model, folder, views)}
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


def test_the_loop_over_kept_views_composes_the_pairs_the_model_kept(tmp_path):
    """The seven pairs kept each turn 1 degree more than the views are posed: the model's own pairs open the
    loop by 7 degrees, which re-registering the (exactly posed) views would not see. Only the step whose
    pair was set aside (2 -> 3) is measured anew."""
    row = _row(_model(tmp_path, [], pair_error_deg=1.0), tmp_path)
    assert row["loop_deg"] == pytest.approx(7.0, abs=0.3), row["steps"]
    assert [(s["from"], s["to"]) for s in row["steps"] if s["by"] == "icp"] == [(2, 3)]
    assert row["status"] == "missed"


def test_a_view_the_model_re_registered_is_linked_by_its_re_registration_not_its_pairs(tmp_path):
    """View 1 was re-registered onto view 0 (its pairs' transforms no longer pose it): its pairs, 20 degrees
    off, are not composed; the re-registration (the pose itself) links it to view 0, ICP of the posed views
    links it to view 2."""
    model = _model(tmp_path, [], reregistered={"view": 1, "position": 1, "fitness": 0.97,
                                               "tried": [{"from_view": 0, "fitness": 0.97, "correction_deg": 1.0},
                                                         {"from_view": 2, "fitness": 0.1, "correction_deg": 9.0}]})
    for e in model["edges"][:2]:
        e["T"] = _rot_z(20.0).tolist()
    row = _row(model, tmp_path)
    by = {(s["from"], s["to"]): s["by"] for s in row["steps"]}
    assert by[(0, 1)] == "pair" and by[(1, 2)] == "icp" and by[(2, 3)] == "icp"
    assert row["loop_deg"] < 0.5 and row["status"] == "closed", row["reason"]
