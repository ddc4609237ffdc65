"""``objscan bench completion``: the generated families cover the ranges the benchmark promises, and every run
that stops is reported with a named limit and the recoveries tried (the scans themselves are the bench's run)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench.completion import FAMILIES, FRICTION, HEIGHT_M, MASS_KG, WIDTH_M, draw, mesh_for, outcome, write_object

trimesh = pytest.importorskip("trimesh")


def test_the_families_cover_the_ranges_and_fit_the_gripper_across_one_direction():
    for family in FAMILIES:
        specs = [draw(family, i, 6, 3) for i in range(6)]
        assert specs == [draw(family, i, 6, 3) for i in range(6)]  # one seed, one set of objects
        heights = [s["height_m"] for s in specs]
        assert HEIGHT_M[0] <= min(heights) and max(heights) <= HEIGHT_M[1]
        assert max(heights) - min(heights) > 0.08  # stratified: short and tall ones in every family
        for s in specs:
            assert WIDTH_M[0] <= s["width_m"] <= WIDTH_M[1] < 0.106  # the gripper opens 10.6 cm
            assert MASS_KG[0] <= s["mass_kg"] <= MASS_KG[1] and FRICTION[0] <= s["friction"] <= FRICTION[1]
            mesh = mesh_for(s)
            assert mesh.is_watertight
            ext = mesh.extents
            assert ext[2] == pytest.approx(s["height_m"], abs=1e-6) and abs(mesh.bounds[0][2]) < 1e-9
            assert WIDTH_M[0] - 1e-6 <= min(ext[0], ext[1]) <= WIDTH_M[1] + 1e-6  # one grasp direction fits
            assert np.isclose(ext[:2], s["width_m"], rtol=0.02).any()
    assert draw("boxes", 0, 4, 3) != draw("boxes", 0, 4, 4)


def test_an_object_is_written_with_its_mass_and_friction(tmp_path):
    spec = draw("bottles", 1, 4, 3)
    path = write_object(spec, tmp_path, "bottle")
    physics = json.loads((tmp_path / "bottle.ply.physics.json").read_text())
    assert physics == {"mass_kg": spec["mass_kg"], "friction": spec["friction"]}
    mesh = trimesh.load(path)
    assert len(np.unique(np.asarray(mesh.visual.vertex_colors)[:, :3], axis=0)) == 2  # striped: texture to register


def test_every_stop_names_its_limit_and_the_recoveries_tried():
    reach = {"status": "failed", "view": 4, "counters": {"rescans": 2, "repositions": 1},
             "error": {"code": "acquisition_failed", "message": "view 4: giving up after 2 re-scans (no executable "
                       "grasp); limit: reach: every planned grasp, turn or set-down leaves the arm's reachable "
                       "workspace (joint_limits x12); recovery tried: re-scan, top-down grasps, reposition"}}
    o = outcome(reach)
    assert o["limit"] == "reach" and o["view"] == 4
    assert o["recoveries_tried"] == ["re-scan", "top-down grasps", "reposition"]
    assert o["recoveries_executed"]["repositions"] == 1
    topple = {"status": "failed", "error": {"code": "acquisition_failed", "message": "view 2: the object's height "
              "changed ...; giving up; limit: stability: the object does not stay standing; recovery tried: none"}}
    assert outcome(topple)["limit"] == "stability"
    crash = {"status": "failed", "error": {"code": "internal", "message": "KeyError at /tmp/x/y"}}
    assert outcome(crash)["limit"] == "unnamed (internal)" and "/tmp/" not in outcome(crash)["message"]
    done = outcome({"status": "done", "accuracy": {"chamfer_mm": 1.2}, "counters": {}})
    assert done["status"] == "done" and done["chamfer_mm"] == 1.2 and "limit" not in done


def test_the_cli_passes_runs_and_seed_to_the_completion_bench_and_refuses_them_elsewhere(monkeypatch):
    import argparse
    import importlib

    from services.cli import cmd_bench
    from services.cli.outcome import BadUsage

    parser = argparse.ArgumentParser()
    cmd_bench.register(parser.add_subparsers())
    seen: dict = {}
    completion = importlib.import_module("bench.completion")
    monkeypatch.setattr(completion, "run", lambda quick=False, runs=None, views=None, seed=3, families=():
                        seen.update(quick=quick, runs=runs, seed=seed) or {"families": [], "runs": 0})
    monkeypatch.setattr(cmd_bench, "print_figures", lambda name, figures: None)
    args = parser.parse_args(["bench", "completion", "--runs", "2", "--seed", "7"])
    assert args.func(args) == 0 and seen == {"quick": False, "runs": 2, "seed": 7}
    with pytest.raises(BadUsage, match="--runs must be at least 1"):
        args.func(parser.parse_args(["bench", "completion", "--runs", "0"]))
    with pytest.raises(BadUsage, match="takes no --seed"):
        args.func(parser.parse_args(["bench", "static", "--seed", "1"]))
