"""The acquisition's parts called on their own: the turn journal, the ground-truth evaluation, the report and
the library insert. Each is a small module the state machine calls; these tests call them directly, without
a cell or a service."""

from __future__ import annotations

import asyncio
import json

import numpy as np
import pytest

from common.api import ModelResult
from common.messages import PointCloud
from services.orchestrator.ground_truth import accuracy_figures, journal_accuracy, truth_in_first_view
from services.orchestrator.journal import Journal
from services.orchestrator.library_insert import insert_session_model, insert_session_model_async
from services.orchestrator.session_report import acquisition_report, model_lateness_s, write_report
from services.orchestrator.states import State
from services.orchestrator.turn_journal import TurnJournal, released_at
from services.session_store import SessionStore


def _pose(yaw_deg: float, t: tuple[float, float, float]) -> np.ndarray:
    a = np.radians(yaw_deg)
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    T[:3, 3] = t
    return T


def _box_surface(n: int = 3000, seed: int = 0) -> np.ndarray:
    """Points on the surface of a 6 x 4 x 10 cm box (object frame, base on z = 0)."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(-1, 1, (n, 3)) * [0.03, 0.02, 0.05]
    face = rng.integers(0, 3, n)
    p[np.arange(n), face] = np.sign(p[np.arange(n), face]) * np.array([0.03, 0.02, 0.05])[face]
    return p + [0, 0, 0.05]


# ------------------------------------------------------------------------------------------ ground truth
def test_truth_is_posed_where_the_object_stood_in_view_0():
    surface = _box_surface()
    T0, T_now = _pose(0.0, (0.4, 0.0, 0.0)), _pose(90.0, (0.3, 0.1, 0.0))
    now = surface @ T_now[:3, :3].T + T_now[:3, 3]
    posed = truth_in_first_view(now, T_now, T0)
    np.testing.assert_allclose(posed, surface @ T0[:3, :3].T + T0[:3, 3], atol=1e-12)
    np.testing.assert_array_equal(truth_in_first_view(now, T_now, None), now)  # no view-0 pose: as it is


def test_accuracy_figures_find_a_shifted_model_and_keep_the_raw_figures():
    gt = _box_surface(4000, seed=1)
    model = _box_surface(4000, seed=2) + [0.002, 0.0, 0.0]  # 2 mm off: ICP from the true pose removes it
    out = accuracy_figures(model, gt, posed_from_truth=True)
    assert out["gt_posed_from_truth"] is True
    assert out["unaligned"]["chamfer_mm"] > out["chamfer_mm"]
    assert out["chamfer_mm"] < 2.0
    kept = journal_accuracy(out)
    assert set(kept) <= {"chamfer_mm", "accuracy_mm", "completeness_mm", "fscore_2mm", "fscore_5mm"}
    assert kept["chamfer_mm"] == out["chamfer_mm"]


# ------------------------------------------------------------------------------------------ turn journal
def _journal(tmp_path, views: int = 3) -> tuple[Journal, SessionStore]:
    store = SessionStore(tmp_path / "s")
    j = Journal(config={"views": views})
    j.centers["0"], j.heights["0"] = [0.4, 0.0, 0.0], 0.1
    return j, store


def test_a_recorded_turn_adds_the_next_view_and_is_on_disk(tmp_path):
    j, store = _journal(tmp_path)
    turns = TurnJournal(j, store, turn_deg=30.0)
    turns.intent("closing", release_T=np.eye(4).tolist())
    assert store.load_journal()["turn_intent"]["phase"] == "closing"
    assert store.load_journal()["turn_intent"]["view"] == 0
    turns.intent("holding", direction=-1)
    assert store.load_journal()["holding"] is True
    turns.record_turn(0, -1, np.array([0.05, 0.0, 0.0]))
    on_disk = store.load_journal()
    assert on_disk["view"] == 1 and on_disk["turns_deg"] == [0.0, -30.0] and on_disk["turn_direction"] == -1
    assert on_disk["turn_intent"] is None and on_disk["holding"] is False and on_disk["state"] == State.SCAN
    assert on_disk["centers"]["1"] == pytest.approx([0.45, 0.0, 0.0])


def test_a_reposition_keeps_the_view_and_moves_its_frames_aside(tmp_path):
    j, store = _journal(tmp_path)
    (store.path / "view_00").mkdir()
    (store.path / "view_00" / "frame").write_text("kept")
    TurnJournal(j, store, turn_deg=30.0).record_turn(0, 0, np.array([0.0, 0.1, 0.0]))  # no turn: a reposition
    on_disk = store.load_journal()
    assert on_disk["view"] == 0 and on_disk["turns_deg"] == [0.0] and on_disk["pending_rescan"] is None
    assert on_disk["regrasps"]["0"][0]["strategy"] == "reposition"
    assert (store.path / "view_00_moved1" / "frame").read_text() == "kept"
    assert not (store.path / "view_00").exists()


def test_a_rescan_is_journalled_before_its_old_attempt_moves_aside(tmp_path, monkeypatch):
    j, store = _journal(tmp_path)
    (store.path / "view_00").mkdir()
    seen = []
    import shutil

    real_move = shutil.move
    monkeypatch.setattr(shutil, "move", lambda a, b: (seen.append(store.load_journal()["pending_rescan"]),
                                                      real_move(a, b)))
    TurnJournal(j, store, turn_deg=30.0).begin_rescan(0, 1)
    assert seen == [{"view": 0, "attempt": 1}]
    assert (store.path / "view_00_attempt1").is_dir() and j.pending_rescan is None


def test_released_at_needs_the_release_position_and_orientation():
    R = _pose(30.0, (0.4, 0.1, 0.2))
    assert released_at(R, R)
    assert not released_at(_pose(30.0, (0.4, 0.1, 0.22)), R)  # 2 cm off
    assert not released_at(_pose(40.0, (0.4, 0.1, 0.2)), R)  # 10 degrees off


# ------------------------------------------------------------------------------------------ report
def test_the_report_holds_the_model_the_run_and_each_view(tmp_path):
    j, store = _journal(tmp_path, views=2)
    for k in range(2):
        store.save_json(f"view_{k:02d}/view.json", {"figures": {"view": k}})
    j.model_path, j.model_accepted, j.model_why = str(store.path / "model.ply"), True, ""
    j.decisions.append({"what": "model built"})
    cloud = PointCloud(xyz=np.zeros((5, 3)))
    report = acquisition_report(j, store, ModelResult(cloud=cloud, figures={"accepted": True}), [0.0, 30.0],
                                incremental=True, accuracy={"chamfer_mm": 1.5})
    path = write_report(store, report)
    on_disk = json.loads(path.read_text())
    assert on_disk["points"] == 5 and on_disk["turns_commanded_deg"] == [0.0, 30.0]
    assert on_disk["accuracy"] == {"chamfer_mm": 1.5} and on_disk["views"] == [{"view": 0}, {"view": 1}]
    assert on_disk["decisions"] == [{"what": "model built"}] and on_disk["session"] == str(store.path)
    no_truth = acquisition_report(j, store, ModelResult(cloud=cloud), [0.0, 30.0], incremental=False)
    assert "accuracy" not in no_truth


def test_model_lateness_is_none_without_the_last_scan(tmp_path):
    _, store = _journal(tmp_path)
    model = store.path / "model.ply"
    model.write_text("ply")
    assert model_lateness_s(store, model, 2, 2) is None


# ------------------------------------------------------------------------------------------ library insert
def test_a_library_insert_that_fails_says_why_and_never_raises(tmp_path):
    not_a_session = tmp_path / "empty"
    not_a_session.mkdir()
    out = insert_session_model(tmp_path / "lib", not_a_session)
    assert not out.ok and out.entry is None and out.error
    assert not asyncio.run(insert_session_model_async(tmp_path / "lib", not_a_session)).ok


# ------------------------------------------------------------------------------------------ cell set-up
class _Cell:
    """A cell whose twin and arm answer as scripted; every call is recorded."""

    def __init__(self, twin: dict | None = None, refuse_first: int = 0):
        self.twin, self.refuse_first, self.calls = twin, refuse_first, []

    async def sim(self, op, **kw):  # noqa: ANN001, ANN003, ANN201
        self.calls.append(("sim", op))
        if self.twin is None:
            from common.errors import RemoteError

            raise RemoteError("no twin", code="unavailable")
        return self.twin

    async def gripper(self, opening, force=None):  # noqa: ANN001, ANN201
        self.calls.append(("gripper", opening))

    async def move(self, kind, **kw):  # noqa: ANN001, ANN003, ANN201
        from types import SimpleNamespace

        from common.errors import RemoteError

        self.calls.append(("move", kind))
        if kind == "pose" and self.refuse_first > 0:
            self.refuse_first -= 1
            raise RemoteError("out of reach", code="unreachable")
        return SimpleNamespace(q=np.zeros(6))


def test_a_twin_states_its_accuracy_and_a_real_cell_the_robot_files(monkeypatch):
    from services.orchestrator.cell_setup import prepare_cell
    from services.orchestrator.config import AcquisitionConfig

    said: list = []
    config, j = AcquisitionConfig(views=3), Journal(config={})
    twin = {"pose_accuracy": {"position_sigma_mm": 2.0, "orientation_sigma_deg": 0.5}, "turn_accuracy_deg": 1.5}
    cell = _Cell(twin)
    asyncio.run(prepare_cell(cell, config, j, lambda what, **kw: said.append(what)))
    assert j.simulated is True and config.turn_accuracy_deg == 1.5 and j.config["turn_accuracy_deg"] == 1.5
    assert j.config["pose_accuracy"] == config.pose_accuracy and config.pose_accuracy
    assert cell.calls[0] == ("sim", "reset") and cell.calls[-1][0] == "gripper" and said == ["cell ready"]

    real, j2, config2 = _Cell(None), Journal(config={}), AcquisitionConfig(views=3)
    asyncio.run(prepare_cell(real, config2, j2, lambda what, **kw: None))
    assert j2.simulated is False and config2.pose_accuracy  # the robot file's (or the conservative default)
    asyncio.run(prepare_cell(real, config2, j2, lambda what, **kw: None))  # a resume: the twin is not reset
    assert [c for c in real.calls if c[0] == "sim"] == [("sim", "reset")]


# ------------------------------------------------------------------------------------------ scan reach
def test_the_first_reachable_scan_set_skips_refused_ones_and_a_spot_is_checked_once():
    from services.orchestrator.config import AcquisitionConfig
    from services.orchestrator.scan_reach import first_reachable_scan_set, scannable_spot

    scan = AcquisitionConfig(views=3).scan
    cell = _Cell(refuse_first=1)
    poses, reasons = asyncio.run(first_reachable_scan_set(cell, scan, np.array([0.4, 0.0, 0.0]), 0.1))
    assert poses is not None and reasons == ["unreachable"]
    cache: dict = {}
    said: list = []
    spot = np.array([0.35, 0.05, 0.0])
    assert asyncio.run(scannable_spot(cell, scan, spot, 0.1, cache, lambda what, **kw: said.append(what)))
    moves = len(cell.calls)
    assert asyncio.run(scannable_spot(cell, scan, spot + 1e-5, 0.1, cache, lambda what, **kw: None))
    assert len(cell.calls) == moves and said == []  # the same spot (to the millimetre): not asked again
    never = _Cell(refuse_first=10 ** 6)
    assert not asyncio.run(scannable_spot(never, scan, spot, 0.1, {}, lambda what, **kw: said.append(what)))
    assert said == ["relocated spot leaves no reachable scan poses"]
