"""``reconstruct`` over a session folder written by the digital twin."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from common.session_folder import SessionFolderError, scan_dir
from services.registration.cloud import read_ply
from services.registration.reconstruct import reconstruct

scenario = pytest.importorskip("bench.scenario", reason="the digital twin (services/sim) is not available")


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    views = scenario.simulated_views("cream_cheese", views=3, scans_per_view=3, profile="robot-turned", seed=4)
    path = scenario.write_session(tmp_path_factory.mktemp("sess") / "session", views)
    # view 2: the first scan's depth is all zero (a camera that returned nothing)
    Image.fromarray(np.zeros((480, 640), dtype=np.uint16)).save(scan_dir(path, 2, 0) / "depth.png")
    return path


@pytest.fixture(scope="module")
def report(session, tmp_path_factory):
    out = tmp_path_factory.mktemp("out")
    events = []
    rep = reconstruct(session, out, progress=events.append, workers=2)  # two worker processes
    return out, rep, events


def test_writes_one_ply_per_good_view_in_base(session, report):
    out, rep, _ = report
    truth = json.loads((session / "session.json").read_text())["views"]
    for k in (0, 1):
        cloud = read_ply(out / "views" / f"view_{k:02d}.ply")
        assert len(cloud) > 500 and cloud.rgb is not None and cloud.normals is not None
        v = rep["views"][k]
        assert v["ply"] == f"views/view_{k:02d}.ply" and v["object_points"] == len(cloud)
        # in base: the object stands on the table where the twin put it, z up
        T_obj = np.asarray(truth[k]["ground_truth"]["T_base_object"])
        assert np.linalg.norm(np.asarray(v["object_center"])[:2] - T_obj[:2, 3]) < 0.01
        assert cloud.xyz[:, 2].min() > 0.0 and cloud.xyz[:, 2].max() < 0.25
    assert not (out / "views" / "view_02.ply").exists()


def test_report_has_figures_timings_and_ground_truth(report):
    out, rep, events = report
    on_disk = json.loads((out / "report.json").read_text())
    assert on_disk["summary"] == rep["summary"]
    assert rep["summary"]["views"] == 3 and rep["summary"]["views_ok"] == 2
    assert rep["summary"]["views_failed"] == [2]
    assert rep["views"][2]["error"]["code"] == "empty_depth"
    for v in rep["views"][:2]:
        assert v["timings_s"]["total"] > 0 and len(v["scans"]) == 3
        assert v["ground_truth"]["max_trans_err_mm"] <= 1.0 and v["ground_truth"]["max_rot_err_deg"] <= 0.2
        assert [s["path"] for s in v["scans"]] == ["anchor", "local", "local"]
    assert rep["views"][1]["commanded_turn_deg"] == 30.0
    assert "model" in rep  # the dynamic stage's figures (or its error) go here
    static = [e for e in events if e["stage"] == "static"]
    assert [e["view"] for e in static] == [0, 1, 2] and static[2]["status"] == "failed"


def test_missing_session_is_a_session_error(tmp_path):
    with pytest.raises(SessionFolderError):
        reconstruct(tmp_path / "nope", tmp_path / "out")


def test_worker_processes_do_not_change_the_result(session, report, tmp_path):
    """Two worker processes and a run in this process agree on every figure."""
    _, pooled, _ = report
    here = reconstruct(session, tmp_path / "here", workers=1)
    assert pooled["workers"] == 2 and here["workers"] == 1

    def figures(view: dict) -> dict:
        return {k: v for k, v in view.items() if k not in ("seconds", "timings_s", "cpu_timings_s")}

    assert [figures(v) for v in here["views"]] == [figures(v) for v in pooled["views"]]
    for k in (0, 1):
        a = read_ply(tmp_path / "here" / "views" / f"view_{k:02d}.ply")
        b = read_ply(Path(report[0]) / "views" / f"view_{k:02d}.ply")
        assert np.array_equal(a.xyz, b.xyz) and np.array_equal(a.rgb, b.rgb)


def test_threaded_static_stage_gives_the_serial_poses(session, tmp_path):
    """Views registered by two threads of this process give the same poses and clouds as one by one."""
    serial = reconstruct(session, tmp_path / "serial", workers=1, threads=1)
    threaded = reconstruct(session, tmp_path / "threaded", workers=1, threads=2)
    assert serial["threads"] == 1 and threaded["threads"] == 2

    def figures(view: dict) -> dict:
        return {k: v for k, v in view.items() if k not in ("seconds", "timings_s", "cpu_timings_s")}

    assert [figures(v) for v in threaded["views"]] == [figures(v) for v in serial["views"]]
    for k in (0, 1):
        poses = [np.asarray(s["T_base_camera"]) for s in threaded["views"][k]["scans"]]
        assert all(np.array_equal(a, np.asarray(b["T_base_camera"]))
                   for a, b in zip(poses, serial["views"][k]["scans"], strict=True))
        a = read_ply(tmp_path / "serial" / "views" / f"view_{k:02d}.ply")
        b = read_ply(tmp_path / "threaded" / "views" / f"view_{k:02d}.ply")
        assert np.array_equal(a.xyz, b.xyz) and np.array_equal(a.rgb, b.rgb)


def test_the_static_stage_takes_the_arm_accuracy_the_session_states(session, report):
    """The twin's session states its profile's accuracy; reconstruct registers with it and says so."""
    from services.sim.profiles import get_profile

    _, rep, _ = report
    stated = json.loads((session / "session.json").read_text())["pose_accuracy"]
    assert stated == get_profile("robot-turned").pose_accuracy().to_dict()
    assert rep["pose_accuracy"] == {**stated, "source": "session"}
    assert rep["config"]["arm_position_sigma_mm"] == stated["position_sigma_mm"]
    assert rep["summary"]["scans_left_out"] == {}
    assert all(s["fused"] for v in rep["views"][:2] for s in v["scans"])
