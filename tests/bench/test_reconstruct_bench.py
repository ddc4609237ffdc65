"""``objscan bench reconstruct``: the harsh set's generator, the multiway peer, the summary and the JSON."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench import harsh_set
from bench.reconstruct import set_objects, summarize
from common.errors import ObjscanError
from services.sim.catalogue import load_object
from services.sim.profiles import get_profile

ROOT = Path(__file__).resolve().parents[2]


def _signed_volume(mesh) -> float:  # noqa: ANN001
    v = np.asarray(mesh.vertices)[np.asarray(mesh.triangles)]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum()) / 6.0


@pytest.mark.parametrize("name", harsh_set.NAMES)
def test_harsh_primitives_are_closed_outward_graspable_and_deterministic(name, tmp_path):
    mesh = harsh_set.shape_mesh(name)
    verts = np.asarray(mesh.vertices)
    extent = verts.max(0) - verts.min(0)
    assert max(extent[:2]) <= 0.080  # the gripper's reach across
    assert 0.09 <= extent[2] <= 0.20
    assert verts[:, 2].min() == pytest.approx(0.0)  # stands on the table
    assert _signed_volume(mesh) > 0  # wound outward
    np.testing.assert_array_equal(verts, np.asarray(harsh_set.shape_mesh(name).vertices))
    path = harsh_set.write_mesh(name, tmp_path)
    assert path.parent == tmp_path
    obj = load_object(str(path))
    shape = next(s for s in harsh_set.SHAPES if s.name == name)
    assert (obj.appearance != "untextured") == shape.textured
    np.testing.assert_allclose(obj.extent, extent, atol=1e-6)


def test_the_cylinder_is_the_true_circle_within_a_tenth_of_a_millimetre():
    mesh = harsh_set.shape_mesh("cylinder")
    assert _signed_volume(mesh) == pytest.approx(np.pi * 0.035**2 * 0.110, rel=2e-3)
    assert not any(s.textured for s in harsh_set.SHAPES if s.name in ("box", "cylinder"))


def test_the_harsh_profile_is_realistic_pushed_to_the_stated_errors():
    harsh, realistic = get_profile("harsh"), get_profile("realistic")
    assert harsh.scan_pose_mm[1] > 3.0 and harsh.scan_pose_deg[1] > 1.0  # "about 3 mm / 1 degree and beyond"
    assert harsh.turn_clip_deg == 8.0 and harsh.turn_sigma_deg > realistic.turn_sigma_deg
    assert harsh.place_shift_sigma_m * np.sqrt(np.pi / 2) == pytest.approx(0.0044, abs=0.001)  # mean |shift| ~5 mm
    assert harsh.camera == realistic.camera and harsh.hand_eye_mm == realistic.hand_eye_mm


def test_a_harsh_session_records_the_primitive_with_its_ground_truth(tmp_path):
    session = harsh_set.session_for("box", tmp_path, views=2, scans_per_view=1)
    data = json.loads((session / "session.json").read_text())
    assert data["profile"] == "harsh" and data["source"] == "sim"
    assert Path(data["ground_truth"]["object_model"]["source"]).parent == tmp_path / "meshes"
    turns = [v["ground_truth"]["achieved_turn_deg"] for v in data["views"]]
    assert [v["commanded_turn_deg"] for v in data["views"]] == [0.0, 30.0]
    assert turns[0] == 0.0 and abs(turns[1] - 30.0) <= 8.0 + 1e-9
    assert (session / "view_01" / "scan_0" / "depth.png").is_file()
    assert harsh_set.session_for("box", tmp_path, views=2, scans_per_view=1) == session  # reused


def test_the_sets_and_their_quick_picks():
    assert set_objects("harsh") == [("harsh", n) for n in harsh_set.NAMES]
    assert set_objects("all", quick=True) == [("harsh", "box"), ("realistic", "milk")]
    assert [s for s, _ in set_objects("all")].count("realistic") == 3
    with pytest.raises(ObjscanError) as err:
        set_objects("textured")
    assert err.value.code == "bad_value"


def _row(name: str, seconds: float, ratio: float | None, peer: float | None, accepted: bool = True) -> dict:
    row = {"set": "harsh", "object": name, "seconds": seconds, "cpu_s": seconds, "accepted": accepted}
    if ratio is not None:
        row.update({"chamfer_mm": ratio, "oracle_chamfer_mm": 1.0, "over_oracle": ratio, "chamfer_ratio": ratio,
                    "static_s_per_view": 0.5, "global_fallbacks": 0})
    if peer is not None:
        row.update({"peer_seconds": peer * seconds, "peer_ratio": peer, "peer_chamfer_ratio": 1.0})
    return row


def test_the_summary_checks_every_target_on_every_object():
    good = [_row("a", 10.0, 1.1, 4.0), _row("b", 12.0, 1.2, 3.5), _row("c", 14.0, 1.0, 2.0)]
    s = summarize(good)
    assert (s["median_wall_s"], s["max_wall_s"], s["median_peer_ratio"]) == (12.0, 14.0, 3.5)
    assert s["meets_accuracy_target"] and s["meets_wall_target"] and s["meets_max_wall_target"]
    assert s["meets_peer_ratio_target"]
    slow = summarize([*good[:2], _row("c", 21.0, 1.0, 2.0)])
    assert slow["meets_wall_target"] and not slow["meets_max_wall_target"]
    wrong = summarize([*good[:2], _row("c", 14.0, 1.31, 2.0)])
    assert not wrong["meets_accuracy_target"] and wrong["max_over_oracle"] == 1.31
    no_model = summarize([*good[:2], _row("c", 9.0, None, None, accepted=False)])
    assert not no_model["meets_accuracy_target"]  # an object without a model is not within anything
    assert no_model["accepted"] == 2


def test_the_peer_registers_a_session_from_its_raw_frames_alone(tmp_path):
    """The tutorial peer on a recorded 3-view session: it isolates each view itself and its view poses land
    near the true object motion."""
    from bench.multiway_peer import run_peer
    from common.geometry import invert

    session = harsh_set.session_for("box", tmp_path, views=3, scans_per_view=2)
    figures = run_peer(session, tmp_path / "peer.ply", threads=1)
    assert figures["views"] == [0, 1, 2] and figures["pairs"] == 3
    assert (tmp_path / "peer.ply").is_file() and figures["points"] > 1000
    truth = [np.asarray(v["ground_truth"]["T_base_object"])
             for v in json.loads((session / "session.json").read_text())["views"]]
    centre = truth[0][:3, 3] + np.array([0.0, 0.0, 0.05])  # inside the box, in view 0's base frame
    for T_obj, T in zip(truth, figures["poses"], strict=True):
        err = invert(truth[0] @ invert(T_obj)) @ np.asarray(T)  # the peer's pose against the object's true motion
        angle = np.degrees(np.arccos(np.clip((np.trace(err[:3, :3]) - 1) / 2, -1, 1)))
        assert angle < 2.5 and np.linalg.norm(err[:3, :3] @ centre + err[:3, 3] - centre) < 0.008


def test_the_peer_is_independent_of_objscan():
    """The peer imports only Open3D and NumPy: nothing of objscan's pipeline can run inside its time (the
    ``bench`` package's own start-up only defers Open3D's browser viewer)."""
    code = ("import runpy, sys; runpy.run_module('bench.multiway_peer', run_name='peer'); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('services', 'common', 'bench')))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "['bench', 'common', 'common.open3d_import']"


def test_the_printed_table_labels_each_object_by_set_and_name():
    from bench.report import flatten

    rows = flatten({"objects": [{"set": "harsh", "object": "box", "seconds": 1.5, "dynamic_timings": {"fuse_s": 0.1}}],
                    "median_wall_s": 1.5})
    assert rows == [("objects.harsh:box.seconds", 1.5), ("objects.harsh:box.dynamic_timings.fuse_s", 0.1),
                    ("median_wall_s", 1.5)]


def test_set_is_refused_by_a_bench_without_object_sets(capsys):
    from services.cli.cmd_bench import available
    from services.cli.main import main

    assert "harsh_set" not in available() and "multiway_peer" not in available() and "reconstruct" in available()
    assert main(["bench", "transport", "--quick", "--set", "harsh"]) == 2
    captured = capsys.readouterr()
    assert captured.err.splitlines() == ["objscan bench: transport has no object sets (--set is for reconstruct) "
                                         "[bad_usage]"] and captured.out == ""


@pytest.mark.slow
def test_bench_reconstruct_writes_every_object_with_the_peer(tmp_path):
    """``objscan bench reconstruct --set harsh --quick --json F``: the box, objscan and the peer, one entry."""
    out = tmp_path / "figures.json"
    env = {**os.environ, "OBJSCAN_BENCH_SESSION_DIR": str(tmp_path / "sessions")}
    proc = subprocess.run([sys.executable, "-m", "services.cli", "bench", "reconstruct", "--set", "harsh",
                           "--quick", "--json", str(out)], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    figures = json.loads(out.read_text())
    assert figures["sets"] == ["harsh"] and [o["object"] for o in figures["objects"]] == ["box"]
    box = figures["objects"][0]
    for key in ("chamfer_ratio", "seconds", "peer_seconds", "set", "object", "chamfer_mm", "oracle_chamfer_mm",
                "peer_chamfer_mm", "accepted", "cpu_s", "global_fallbacks", "configurations_run"):
        assert key in box, key
    assert box["chamfer_ratio"] == pytest.approx(box["chamfer_mm"] / box["oracle_chamfer_mm"], rel=1e-3)
    assert box["peer_seconds"] > 0 and box["peer_cpu_s"] > 0 and box["peer_chamfer_mm"] > 0
    for key in ("median_wall_s", "max_wall_s", "median_peer_ratio", "meets_accuracy_target", "meets_wall_target",
                "meets_max_wall_target", "meets_peer_ratio_target", "per_object", "by_set"):
        assert key in figures, key
    assert (tmp_path / "sessions" / "meshes" / "box.ply").is_file()
