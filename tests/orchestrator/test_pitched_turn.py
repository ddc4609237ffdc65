"""A box only a pitched pick can hold is turned by it: picked pitched, carried to 0.425 m from the base, stood upright
turned, and the acquisition goes on. A generated slab 5.4 cm thin along the line from the base, 15.8 cm across
(wider than the 10.6 cm stroke), 15.3 cm tall, at the workspace centre (0.60 m): no frontal or top-down turn of
it reaches there, and lying on its other edge it would be no lower, so before this move it stopped at view 0
"limit: reach". The arm is the real kinematics (its own line checks), the planner the real one.
"""

from __future__ import annotations

import asyncio
from dataclasses import replace

import numpy as np
import pytest

from services.arm.kinematics import Kinematics
from services.grasp.planner import plan_grasps
from services.grasp.service import GraspService
from services.orchestrator.config import RelocationConfig, TurnMotion
from services.orchestrator.lay_down import whole_object
from services.orchestrator.machine import State
from services.orchestrator.pitched_turn import QUARTER_TURN, pitched_turn_sequences, turn_direction
from services.orchestrator.pitched_turn_step import STAND_RADIUS, stand_shifts, turn_angles
from tests.grasp.shapes import table_plane
from tests.orchestrator.test_lay_down import THIN_WIDE_BOX, WORKSPACE, _held, _standing_tall_box, _view
from tests.orchestrator.test_recovery import _steps


@pytest.fixture(scope="module")
def kin() -> Kinematics:
    return Kinematics()


def _pitched_chains(angles: tuple[float, ...]):  # noqa: ANN202
    view = _view(THIN_WIDE_BOX, WORKSPACE, 0)
    plan = plan_grasps(view.cloud.xyz, view.cloud.normals, table_plane(),
                       replace(GraspService.planner_config(), mode="top_down"))
    grasps = plan.to_messages()
    seqs = [s for g in grasps for s in pitched_turn_sequences(g, view.cloud.xyz, view.center, view.height,
                                                                TurnMotion(), stand_shifts(view.center,
                                                                                           RelocationConfig()),
                                                                angles)]
    return view, grasps, seqs


@pytest.mark.parametrize("angle", [30.0, -90.0])
def test_the_slab_is_stood_upright_turned_near_the_base_by_a_pitched_pick(kin, angle):
    """A chain of the pitched pick is executable in full for the view's turn and for a quarter turn either way;
    it sets the slab down upright, turned by that angle about its vertical, just above the table on the near
    ring; the hand leaves leaning away from the base (straight up it cannot: a straight-down hand reaches only
    15 cm high there)."""
    from tests.orchestrator.test_turn_reach import _executable

    view, grasps, seqs = _pitched_chains((angle,))
    ok = next((s for s in seqs if np.linalg.norm(s.carry) > 0 and _executable(kin, s)), None)
    assert ok is not None, sorted({s.name for s in seqs})
    pts = whole_object(view.cloud.xyz, view.center)
    assert ok.lean_deg > 0 and ok.retreat[2, 3] > ok.turned[2, 3] + 0.05
    for seq in seqs:
        assert "_pitch" in seq.name and seq.direction == turn_direction(angle, 30.0)
        assert abs(seq.direction) == (1 if abs(angle) == 30.0 else QUARTER_TURN)
        rest = seq.turned @ _held(grasps, seq)  # the slab's motion from where it stood to where it is released
        assert rest[2, 2] == pytest.approx(1.0, abs=1e-6)  # upright
        assert np.degrees(np.arctan2(rest[1, 0], rest[0, 0])) == pytest.approx(angle, abs=1e-6)
        moved = pts @ rest[:3, :3].T + rest[:3, 3]
        assert float(moved[:, 2].min()) == pytest.approx(float(pts[:, 2].min()) + 0.004, abs=1e-6)
        for mv in seq.straight_moves(view.center):  # held from the lift to the set-down: above the table
            if mv.phase == "held":
                M = mv.target @ _held(grasps, seq)
                assert float((pts @ M[:3, :3].T + M[:3, 3])[:, 2].min()) > 0.0, mv.step
    assert np.hypot(*(view.center[:2] + ok.carry[:2])) == pytest.approx(STAND_RADIUS, abs=0.01)


def test_the_quarter_turn_comes_first_then_the_views_own_turn():
    assert turn_angles(30.0, None) == [90.0, -90.0, 30.0, -30.0]
    assert turn_angles(30.0, -1) == [-90.0, 90.0, -30.0]


@pytest.mark.slow  # every standing chain is dry-run first, as in a real acquisition: ~20 s idle
def test_the_state_machine_turns_the_slab_by_its_pitched_pick_and_goes_on(kin, tmp_path):
    """In the state machine at view 0 with top-down grasps planned: no turn, relocated set-down or reposition
    of them is executable, so the slab is stood a quarter turn round by its pitched pick, 0.425 m from the
    base, and view 0 is scanned again there (no view kept yet: its frame starts there)."""
    cell, acq = _standing_tall_box(kin, tmp_path, rescans=0, size=THIN_WIDE_BOX)
    acq.j.grasp_mode = "top_down"
    states = asyncio.run(_steps(acq, 4))
    assert states[-1] == State.SCAN, acq.j.decisions[-5:]
    assert acq.view == 0 and acq.j.turns_deg == [0.0], acq.j.decisions[-3:]
    entries = acq.j.regrasps["0"]
    assert any(e["strategy"] == "pitched turn" and "_pitch" in e["pose"] and abs(e["turn_deg"]) == 90.0
               for e in entries)
    assert any(e["strategy"] == "quarter turn" for e in entries)
    assert np.hypot(*acq.j.centers["0"][:2]) == pytest.approx(STAND_RADIUS, abs=0.01)  # the next scan poses: there
    assert {"pitched turn", "quarter turn"} <= set(acq._recoveries_tried(0))
    assert [m for m in cell.log if not m["dry_run"]]  # the arm ran it


@pytest.mark.parametrize("k", [0, 2])
def test_a_quarter_turn_is_recorded_with_its_turn_and_the_view_is_scanned_again(tmp_path, k):
    """The record at the release of a quarter turn: the view is scanned again where the slab now stands (its
    old frames kept aside), its commanded turn grown by the quarter turn when earlier views are kept (the
    registration's turn prior is the turn made), untouched at view 0 (where the object's frame starts); the
    journal says which move it was."""
    from services.orchestrator.config import AcquisitionConfig
    from services.orchestrator.machine import Acquisition
    from services.session_store import SessionStore

    store = SessionStore(tmp_path)
    for v in range(k + 1):
        store.save_view(_view(THIN_WIDE_BOX, WORKSPACE, v))
    acq = Acquisition(object(), store, AcquisitionConfig(views=12))  # type: ignore[arg-type]
    turns = [30.0 * v for v in range(k + 1)]
    acq.j.update(view=k, state="turn", turns_deg=list(turns), turn_direction=1 if k else None,
                 centers={"-1": WORKSPACE.tolist(), str(k): WORKSPACE.tolist()},
                 heights={"-1": THIN_WIDE_BOX[2], str(k): THIN_WIDE_BOX[2]})
    shift = np.array([-0.175, 0.0, 0.0])
    acq._record_release(k, -QUARTER_TURN, shift)
    assert acq.view == k and acq.state == State.SCAN and len(acq.j.turns_deg) == k + 1
    assert acq.j.turns_deg[k] == pytest.approx(turns[k] - 90.0 if k else 0.0)
    assert acq.j.turns_deg[:k] == turns[:k]
    assert acq.j.centers[str(k)][:2] == pytest.approx([0.425, 0.0])
    center, _ = acq._object_estimate(k if k > 0 else -1)  # where the view's scan poses are placed around
    assert center[:2] == pytest.approx([0.425, 0.0])
    assert (tmp_path / f"view_{k:02d}_quarter1").is_dir() and not store.has_view(k)
    entry = acq.j.regrasps[str(k)][-1]
    assert entry["strategy"] == "quarter turn" and entry["turn_deg"] == -90.0
    assert acq.j.counters.repositions == 0 and acq.j.turn_direction == (1 if k else None)


def test_after_a_pitched_pick_failed_on_contact_the_other_picks_go_first_and_it_may_turn_again(kin, tmp_path):
    """A pitched pick whose grasp failed on contact (MuJoCo: a pad landed on the slab) does not use up the
    view's pitched turn: the next plan tries it again, the picks that did not fail first."""
    from services.orchestrator.pitched_turn_step import chains, try_pitched_turn

    cell, acq = _standing_tall_box(kin, tmp_path, rescans=1, size=THIN_WIDE_BOX)
    view = acq.store.load_view(0)
    acq._plan = asyncio.run(cell.plan_grasps(view.cloud, view.table, "top_down"))
    first = chains(acq, view)[0][1].name
    pick = first.split("_turn")[0]
    acq.j.failed_grasps["0"] = [f"top_down:0:{first}"]
    acq.j.regrasps["0"] = [{"strategy": "pitched turn", "pose": first, "slipped": True, "restart": 0}]
    with pytest.MonkeyPatch.context() as mp:
        tried: list[str] = []

        async def refuse(k, chain, center, width, failures):  # noqa: ANN001, ANN202
            tried.append(chain.name)
            return None

        mp.setattr(acq, "_dry_run", refuse)
        assert asyncio.run(try_pitched_turn(acq, 0, view, (np.zeros(3), np.zeros(3)), [])) is None
    assert tried and not tried[0].startswith(pick + "_turn")
    assert "pitched turn (not executable)" not in acq._recoveries_tried(0)  # it was made before, slipping
    acq.j.regrasps["0"] = []
    assert "pitched turn (not executable)" in acq._recoveries_tried(0)  # the failure summary says it was tried
    acq.j.regrasps["0"] = [{"strategy": "pitched turn", "pose": first, "slipped": True, "restart": 0}]
    acq.j.regrasps["0"][0].pop("slipped")  # one that was made: not again at this view
    n = len(acq.j.decisions)
    assert asyncio.run(try_pitched_turn(acq, 0, view, (np.zeros(3), np.zeros(3)), [])) is None
    assert len(acq.j.decisions) == n  # not even tried


def test_a_pitched_pick_opens_wider_than_its_width_and_margin_but_not_fully():
    """Its tilted pads reach into the box opened to the width and margin (the twin: failed on contact)."""
    from services.orchestrator.motion import FULL_OPENING, PITCHED_OPENING, pick_opening

    assert pick_opening(0.0545, 0.04, False) == pytest.approx(0.0945)
    assert 0.0945 < PITCHED_OPENING < 0.098
    assert pick_opening(0.0545, 0.04, True) == pytest.approx(PITCHED_OPENING)
    assert PITCHED_OPENING < FULL_OPENING
    assert pick_opening(0.09, 0.04, True) == pytest.approx(FULL_OPENING)
