"""``bench grasping``: the start poses rest on the table (standing ones tallest), and a table row counts
what the attempts did."""

from __future__ import annotations

import numpy as np
import pytest

from bench.grasping import _row, initial_orientations, resting_height, resting_pose
from services.sim.catalogue import load_object
from services.sim.physics import PhysicsConfig, PhysicsScene
from tests.sim.meshes import write_box_ply


def test_start_poses_rest_on_the_table_and_standing_is_tallest(tmp_path, monkeypatch):
    monkeypatch.setenv("OBJSCAN_CACHE_DIR", str(tmp_path / "cache"))
    box = load_object(str(write_box_ply(tmp_path, (0.06, 0.04, 0.15), name="carton")))
    scene = PhysicsScene(box, config=PhysicsConfig(collision="hull"))
    poses = {name: resting_pose(box, scene, R) for name, R in initial_orientations()}
    assert len(poses) == 7
    heights = {n: resting_height(box, T) for n, T in poses.items()}
    for n, T in poses.items():
        low = (box.vertices @ T[:3, :3].T + T[:3, 3])[:, 2].min()
        assert low == pytest.approx(0.0, abs=0.002), n  # resting on the table, not hovering or sunk
    assert heights["standing_0"] == pytest.approx(0.15, abs=0.002)
    assert heights["side_0"] == pytest.approx(0.04, abs=0.002)  # on its 60 x 150 face
    assert heights["end_0"] == pytest.approx(0.06, abs=0.002)
    assert max(heights, key=heights.get).startswith("standing")
    assert np.degrees(np.arccos(poses["standing_45"][0, 0])) == pytest.approx(45.0, abs=1.0)


def test_a_row_counts_grasps_slips_ranks_and_the_rate():
    attempts = [{"generated": 2, "rank": 8.0, "held": True, "reason": "ok"},
                {"generated": 1, "rank": 7.0, "held": False, "reason": "slip"},
                {"generated": 0, "rank": None, "held": False, "reason": "no_grasp"},
                {"generated": 3, "rank": 9.0, "held": True, "reason": "ok"}]
    r = _row("milk", attempts)
    assert (r["attempts"], r["grasps"], r["slips"]) == (4, 2, 1)
    assert r["avg_rank"] == pytest.approx(8.0) and r["avg_grasp"] == pytest.approx(1.5)
    assert r["grasp_rate"] == pytest.approx(0.5) and r["reasons"] == ["no_grasp", "slip"]


def test_a_turn_is_measured_about_the_table_normal_whatever_side_the_object_lies_on():
    from bench.grasping import turn_figures
    from common.geometry import make_transform, rotation_about_axis

    lying = make_transform(rotation_about_axis([1, 0, 0], np.pi / 2), [0.6, 0.0, 0.03])
    turned = make_transform(rotation_about_axis([0, 0, 1], np.radians(35.0)), [0, 0, 0]) @ lying
    f = turn_figures(lying, turned)
    assert f["degree_change"] == pytest.approx(35.0, abs=1e-6) and f["upright_kept"]
    overturned = make_transform(rotation_about_axis([0, 1, 0], np.pi / 2), [0, 0, 0]) @ lying
    assert not turn_figures(lying, overturned)["upright_kept"]
