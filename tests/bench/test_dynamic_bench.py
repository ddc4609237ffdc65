"""``bench dynamic``: robot-turned rows come from physics acquisitions made once and reused; every row says
which path made it; the paper rows' parallel static stage and its cache compute what the serial one does."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bench import dynamic
from bench.acquired_sessions import AcquisitionBenchError, acquire, session_folder


def _fake_session(folder: Path, status: str, views: int) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "journal.json").write_text(json.dumps({"status": status, "error": None if status == "done" else
                                                     {"code": "limit"}}))
    for k in range(views):
        for j in range(3):
            meta = folder / f"view_{k:02d}" / f"scan_{j}" / "meta.json"
            meta.parent.mkdir(parents=True, exist_ok=True)
            meta.write_text("{}")


def test_a_finished_acquisition_is_reused_not_acquired_again(tmp_path):
    folder = session_folder(tmp_path, "milk", profile="robot-turned", physics="mujoco", seed=0)
    _fake_session(folder, "done", 12)
    calls = []
    acq = acquire("milk", tmp_path, run_scan=lambda cmd, log: calls.append(cmd))
    assert calls == []
    assert (acq.reused, acq.status, acq.views, acq.path) == (True, "done", 12, str(folder))
    assert acq.command.startswith("objscan scan --object milk --physics mujoco --profile robot-turned --views 12")


def test_an_interrupted_acquisition_is_made_again_with_the_scan_command(tmp_path):
    folder = session_folder(tmp_path, "cream_cheese", profile="robot-turned", physics="mujoco", seed=3)
    _fake_session(folder, "running", 4)  # killed mid-run: no finished journal
    (folder / "stale.txt").write_text("from the interrupted run")
    calls = []

    def scan(cmd, log):  # what objscan scan leaves behind when the object cannot be turned to the end
        calls.append(cmd)
        assert not (folder / "stale.txt").exists()  # started from scratch
        _fake_session(folder, "failed", 5)

    acq = acquire("cream_cheese", tmp_path, seed=3, run_scan=scan)
    assert len(calls) == 1
    cmd = calls[0]
    assert cmd[cmd.index("--physics") + 1] == "mujoco" and cmd[cmd.index("--profile") + 1] == "robot-turned"
    assert cmd[cmd.index("--seed") + 1] == "3" and cmd[cmd.index("--out") + 1] == str(folder)
    assert int(cmd[cmd.index("--port") + 1]) > 0  # a private cell, never someone else's default one
    assert (acq.reused, acq.status, acq.views, acq.error) == (False, "failed", 5, {"code": "limit"})


def test_too_few_views_is_a_typed_error(tmp_path):
    with pytest.raises(AcquisitionBenchError) as e:
        acquire("milk", tmp_path, views=1, run_scan=lambda cmd, log: None)
    assert e.value.code == "bad_acquisition_request"


def test_every_row_names_its_path_and_a_failed_acquisition_is_left_out_of_the_table():
    rows = dynamic.ROWS + dynamic.PAPER_ROWS
    assert set(dynamic.ROW_PATHS) == set(rows) == set(dynamic.ROW_LABELS)
    assert {dynamic.ROW_PATHS[r] for r in dynamic.PAPER_ROWS} == {"paper"}
    assert dynamic.ROW_PATHS["auto"] == "fast" and dynamic.ROW_PATHS["oracle"] == "oracle"
    assert dynamic.TURNS["robot-turned"].startswith(dynamic.PHYSICS)
    assert dynamic.TURNS["realistic"].startswith(dynamic.DRAWN)
    per_object = {
        "milk": {"auto": {"chamfer_mm": 1.0, "seconds": 2.0}, "oracle": {"chamfer_mm": 0.8, "seconds": 1.0}},
        "orange_juice": {"auto": {"chamfer_mm": 3.0, "seconds": 4.0}, "oracle": {"chamfer_mm": 1.0, "seconds": 1.0}},
        "cream_cheese": {"acquisition": {"status": "failed"}, "auto": {"error": "acquisition_failed"},
                         "oracle": {"error": "acquisition_failed"}},
    }
    s = dynamic._profile_summary(per_object, ("auto", "oracle"), "robot-turned")
    auto = s["table"]["auto"]
    assert auto["path"] == "fast" and auto["failed_objects"] == ["cream_cheese"]
    assert auto["inclusive_mm"] == pytest.approx(2.0) and auto["exclusive_mm"] == pytest.approx(1.0)
    assert auto["worst_object"] == "orange_juice" and auto["mean_seconds"] == pytest.approx(3.0)
    assert s["objects_not_scored"] == ["cream_cheese"] and s["auto_over_oracle"]["milk"] == pytest.approx(1.25)
    assert s["turns"] == dynamic.TURNS["robot-turned"] and "reconstruct_seconds" not in s


@pytest.fixture(scope="module")
def two_views():
    from bench.scenario import simulated_views

    return simulated_views("milk", views=2, scans_per_view=2, profile="robot-turned", seed=0, intrinsics=None)


@pytest.mark.slow  # rendering the twin's frames: ~30-45 s on the loaded 2-core box
def test_static_views_in_worker_processes_equal_the_serial_ones(two_views):
    serial = dynamic.static_views(two_views)
    pooled = dynamic.static_views(two_views, n_workers=2)
    assert len(serial) == len(pooled) == 2
    for a, b in zip(serial, pooled):
        assert a.index == b.index and a.commanded_turn_deg == b.commanded_turn_deg
        np.testing.assert_array_equal(a.xyz, b.xyz)
        np.testing.assert_array_equal(a.rgb, b.rgb)
        np.testing.assert_array_equal(a.T_view0_view_true, b.T_view0_view_true)


def _tiny_frames(views: int = 2) -> list:
    from common.messages import RGBDFrame

    rng = np.random.default_rng(0)
    return [[RGBDFrame(color=rng.integers(0, 255, (8, 8, 3), dtype=np.uint8),
                       depth=rng.integers(300, 900, (8, 8), dtype=np.uint16), T_base_camera=np.eye(4))
             for _ in range(3)] for _ in range(views)]


def test_the_paper_static_stage_is_cached_per_frames_and_recomputed_for_other_frames(tmp_path, monkeypatch):
    two_views = _tiny_frames()
    calls = []

    def counted(frames, static=None, n_workers=1):
        calls.append(len(frames))
        return [f"view {k}" for k in range(len(frames))]

    monkeypatch.setattr(dynamic, "static_views", counted)
    first, t1 = dynamic.paper_static(two_views, tmp_path)
    again, t2 = dynamic.paper_static(two_views, tmp_path)
    assert calls == [2] and first == again and (t1["static_cached"], t2["static_cached"]) == (False, True)
    assert t2["static_s"] == t1["static_s"]  # the time it took when it was computed, not the cache read
    other = _tiny_frames()
    other[1][0].depth[4, 4] += 1  # one pixel differs
    dynamic.paper_static(other, tmp_path)
    assert calls == [2, 2]  # other frames: not served from the cache


def test_each_row_is_logged_as_measured_when_asked(tmp_path, monkeypatch):
    log = tmp_path / "rows.jsonl"
    dynamic.log_row("milk realistic", "auto", {"chamfer_mm": 1.0})  # no log asked for: nothing written
    assert not log.exists()
    monkeypatch.setenv("OBJSCAN_BENCH_ROW_LOG", str(log))
    dynamic.log_row("milk realistic", "auto", {"chamfer_mm": 1.0, "path": "fast"})
    dynamic.log_row("/s/milk", "paper:region", {"error": "no_table"})
    lines = [json.loads(x) for x in log.read_text().splitlines()]
    assert [(x["where"], x["row"]) for x in lines] == [("milk realistic", "auto"), ("/s/milk", "paper:region")]
    assert lines[0]["chamfer_mm"] == 1.0 and lines[1]["error"] == "no_table" and len(lines[0]["load_average"]) == 3
