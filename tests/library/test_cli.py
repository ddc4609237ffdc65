"""``objscan models`` and ``objscan report`` as a user runs them (the CLI's entry point, in-process)."""

from __future__ import annotations

import json

import numpy as np
import open3d as o3d
import pytest

from services.cli.main import main
from services.library import ModelLibrary
from services.library.descriptors import synthetic_views
from tests.library.helpers import FAST_DESCRIPTORS, box_surface


def objscan(*argv: str) -> int:
    """The command as the CLI runs it: a failure is its one line on stderr and its exit code."""
    return main(list(argv))


@pytest.fixture
def library(tmp_path):
    root = tmp_path / "models"
    lib = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
    ids = {
        "tall red": lib.add(box_surface((0.06, 0.04, 0.14), seed=1, color=(210, 30, 30)), {"object_name": "tall red"}),
        "tall blue": lib.add(box_surface((0.06, 0.04, 0.14), seed=2, color=(30, 40, 200)),
                             {"object_name": "tall blue"}),
        "flat green": lib.add(box_surface((0.12, 0.10, 0.03), seed=3, color=(30, 180, 40)),
                              {"object_name": "flat green"}),
    }
    return root, ids


def test_list_show_export_delete(library, tmp_path, capsys):
    root, ids = library
    assert objscan("models", "--library", str(root), "--json", "list") == 0
    rows = json.loads(capsys.readouterr().out)
    assert sorted(r["object"] for r in rows) == ["flat green", "tall blue", "tall red"]
    assert objscan("models", "--library", str(root), "--json", "show", ids["tall red"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["id"] == ids["tall red"] and shown["points"] == 3000 and len(shown["descriptor"]["whole"]) == 375
    assert objscan("models", "--library", str(root), "export", ids["flat green"], str(tmp_path / "g.ply")) == 0
    assert len(o3d.io.read_point_cloud(str(tmp_path / "g.ply")).points) == 3000
    assert objscan("models", "--library", str(root), "delete", ids["flat green"]) == 0
    capsys.readouterr()
    assert objscan("models", "--library", str(root), "--json", "list", "--object", "flat green") == 0
    assert json.loads(capsys.readouterr().out) == []


def test_unknown_id_exits_2_with_the_error_code(library, capsys):
    root, _ = library
    assert objscan("models", "--library", str(root), "show", "nope") == 2
    assert "model_not_found" in capsys.readouterr().err


def test_find_ranks_the_same_shape_and_print_first(library, tmp_path, capsys):
    root, ids = library
    # a partial view of a fresh "tall blue": the part of its surface a camera at one side sees, turned
    full = box_surface((0.06, 0.04, 0.14), n=6000, seed=9, color=(30, 40, 200))
    view_xyz = next(v for v in synthetic_views(np.asarray(full.points), 8) if len(v) > 1500)
    tree = o3d.geometry.KDTreeFlann(full)
    keep = [tree.search_knn_vector_3d(p, 1)[1][0] for p in view_xyz]
    view = full.select_by_index(keep)
    view.rotate(o3d.geometry.get_rotation_matrix_from_xyz((0, 0, 1.1)), center=(0, 0, 0)).translate((0.3, 0.1, 0))
    o3d.io.write_point_cloud(str(tmp_path / "view.ply"), view)
    assert objscan("models", "--library", str(root), "--json", "find", str(tmp_path / "view.ply"), "--top", "3",
                   "--shortlist", "3") == 0
    matches = json.loads(capsys.readouterr().out)
    assert [m["detail"]["object"] for m in matches][0] == "tall blue"
    assert matches[0]["id"] == ids["tall blue"]
    assert matches[0]["score"] > 2.0 * matches[1]["score"]


def test_report_command_on_a_missing_session_exits_2(tmp_path, capsys):
    assert objscan("report", str(tmp_path / "none")) == 2
    assert "[path_not_found]" in capsys.readouterr().err


