"""Repositioning (services/orchestrator/reposition.py): an object that drifted near the edge of the arm's reach
is picked and set down unturned at a spot the arm works best at, scanned again there, and the acquisition goes
on with its turn bookkeeping exact. Real grasp planner, real arm kinematics and controller (no Zenoh)."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from common.api import GraspPlanReply, ViewResult
from common.messages import PointCloud
from services.arm.drivers.sim import SimArmDriver
from services.arm.kinematics import Kinematics
from services.grasp.planner import plan_grasps
from services.grasp.service import GraspService
from services.orchestrator.config import AcquisitionConfig, ConfigError, RelocationConfig, TurnMotion
from services.orchestrator.machine import Acquisition, State
from services.orchestrator.planning import turn_sequences
from services.orchestrator.regrasp import relocated, relocation_shift
from services.orchestrator.reposition import NO_TURN, drift, favoured_spots, reposition_shifts, without_turn
from services.session_store import SessionStore
from tests.grasp.shapes import cylinder, table_plane
from tests.orchestrator.arm_cell import ArmOnlyCell

CAN = (0.034, 0.10)  # radius, height (m): a squat can
WORKSPACE = np.array([0.60, 0.0, 0.0])


def _view(center: np.ndarray, k: int) -> ViewResult:
    cams = [center + 0.38 * np.array([-np.cos(np.radians(a)), np.sin(np.radians(a)), 0.0]) + [0, 0, 0.3]
            for a in (-22.0, 0.0, 22.0)]
    xyz, normals = cylinder(CAN[0], CAN[1], 6000, xy=center[:2], view_from=cams, noise=0.0005)
    return ViewResult(view=k, cloud=PointCloud(xyz=xyz.astype(np.float32), normals=normals.astype(np.float32)),
                      table=table_plane(), center=center.copy(), height=CAN[1], scan_poses=np.zeros((0, 4, 4)))


def _plan(view: ViewResult) -> GraspPlanReply:
    p = plan_grasps(view.cloud.xyz, view.cloud.normals, view.table, GraspService.planner_config())
    return GraspPlanReply(grasps=p.to_messages(), rejections={}, explanation=p.explain(), seconds=0.0)


def test_favoured_spots_are_the_workspace_centre_then_the_near_ring():
    spots = favoured_spots(WORKSPACE, RelocationConfig())
    np.testing.assert_allclose(spots[0], WORKSPACE)
    assert sorted(round(float(np.hypot(*s[:2])), 3) for s in spots[1:]) == [0.4, 0.4, 0.4]
    assert drift(np.array([0.61, 0.01, 0.0]), spots) < 0.02
    assert drift(np.array([0.66, 0.20, 0.0]), spots) == pytest.approx(np.hypot(0.06, 0.20))
    shifts = reposition_shifts(np.array([0.66, 0.20, 0.0]), spots, 0.02)
    np.testing.assert_allclose(shifts[0], [-0.06, -0.20, 0.0])  # the nearest spot first
    assert all(np.linalg.norm(d) >= 0.02 for d in reposition_shifts(WORKSPACE, spots, 0.02))
    with pytest.raises(ConfigError, match="reposition_drift"):
        RelocationConfig(reposition_drift=-0.1)


def test_a_reposition_picks_and_sets_down_where_it_picked_without_turning():
    seq = turn_sequences(_plan(_view(WORKSPACE, 0)).grasps[0], TurnMotion(), CAN[1])[0]
    still = without_turn(seq)
    assert still.direction == NO_TURN
    np.testing.assert_array_equal(still.turned, seq.grasp)
    np.testing.assert_array_equal(still.turned_lifted, seq.lifted)
    moved = relocated(still, np.array([-0.06, -0.2, 0.0]))
    np.testing.assert_allclose(relocation_shift(moved), [-0.06, -0.2, 0.0])
    np.testing.assert_allclose(moved.turned[:3, :3], seq.grasp[:3, :3])  # set down unturned


@pytest.fixture(scope="module")
def kin() -> Kinematics:
    return Kinematics()


def _brought_back(kin: Kinematics, tmp_path) -> tuple[Acquisition, ArmOnlyCell]:  # noqa: ANN001
    """View 2 of a can standing near the edge of reach, 21 cm off the workspace centre (set down there by
    earlier relocations and pushes): the turn step brings it back."""
    far = np.array([0.66, 0.20, 0.0])
    store = SessionStore(tmp_path)
    store.save_view(_view(far, 2))
    cell = ArmOnlyCell(np.asarray(SimArmDriver(send=lambda q, o: None).config.initial_q, float), kin)
    acq = Acquisition(cell, store, AcquisitionConfig(views=12))  # type: ignore[arg-type]
    acq.j.update(view=2, state="turn", turns_deg=[0.0, 30.0, 60.0], turn_direction=1,
                 centers={"2": far.tolist()}, heights={"2": CAN[1]})
    acq._plan = _plan(store.load_view(2))
    assert asyncio.run(acq.turn()) == State.SCAN
    return acq, cell


def test_an_object_near_the_edge_of_reach_is_brought_back_unturned(kin, tmp_path):
    acq, cell = _brought_back(kin, tmp_path)
    # the same view, the same commanded turns; the view is scanned again where it now stands
    assert acq.view == 2 and acq.j.turns_deg == [0.0, 30.0, 60.0]
    assert acq.j.counters.repositions == 1
    entry = acq.j.regrasps["2"][-1]
    assert entry["strategy"] == "reposition"
    np.testing.assert_allclose(acq.j.centers["2"][:2], WORKSPACE[:2], atol=1e-6)
    assert (tmp_path / "view_02_moved1").is_dir() and not acq.store.has_view(2)  # old frames kept aside
    assert any(d["what"].startswith("repositioned") for d in acq.j.decisions)
    assert [m for m in cell.log if not m["dry_run"] and m["error"]] == []
    assert asyncio.run(acq._reachable_scan_set(2))  # it can be scanned there


@pytest.mark.slow  # two full turn steps on the real kinematics: about 45 s on a loaded 2-core machine
def test_after_the_reposition_the_acquisition_goes_on_with_exact_turns(kin, tmp_path):
    acq, _ = _brought_back(kin, tmp_path)
    acq.store.save_view(_view(WORKSPACE, 2))  # view 2 registered again at the new spot
    acq.j.state = State.TURN.value
    acq._plan = _plan(acq.store.load_view(2))
    assert asyncio.run(acq.turn()) == State.SCAN
    assert acq.view == 3 and acq.j.turns_deg == [0.0, 30.0, 60.0, 90.0]
    assert acq.j.counters.repositions == 1  # at the favoured spot: no second reposition


class _ReleasedCell:
    """The arm stands where a reposition released the object (fingers still closed on it)."""

    def __init__(self, T: np.ndarray):
        self.T = T
        self.openings: list[float] = []

    async def state(self):  # noqa: ANN201
        from common.messages import JointState

        return JointState(names=[], position=np.zeros(6), T_base_gripper=self.T, T_base_camera=np.eye(4),
                          gripper_opening=0.0)

    async def gripper(self, opening: float, force: float = 30.0) -> None:
        self.openings.append(opening)


def test_a_reposition_finished_before_a_restart_is_recorded_not_repeated(tmp_path):
    store = SessionStore(tmp_path)
    store.save_view(_view(np.array([0.66, 0.20, 0.0]), 2))
    release = np.eye(4)
    release[:3, 3] = [0.6, 0.0, 0.05]
    cell = _ReleasedCell(release)
    acq = Acquisition(cell, store, AcquisitionConfig(views=12))  # type: ignore[arg-type]
    acq.j.update(view=2, state="turn", turns_deg=[0.0, 30.0, 60.0], turn_direction=1,
                 centers={"2": [0.66, 0.20, 0.0]}, heights={"2": CAN[1]},
                 turn_intent={"view": 2, "phase": "holding", "direction": NO_TURN, "opening": 0.08,
                              "shift": [-0.06, -0.20, 0.0], "release_T": release.tolist(),
                              "center": [0.66, 0.20, 0.0], "height": CAN[1]})
    asyncio.run(acq._recover_turn())
    assert cell.openings == [0.08]  # released where it was set down, never moved again
    assert acq.view == 2 and acq.j.turns_deg == [0.0, 30.0, 60.0] and acq.state == State.SCAN
    np.testing.assert_allclose(acq.j.centers["2"][:2], [0.60, 0.0], atol=1e-9)
    assert (tmp_path / "view_02_moved1").is_dir() and acq.j.turn_intent is None
