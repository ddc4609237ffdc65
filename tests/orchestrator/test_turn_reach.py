"""The pick-turn-place the arm is asked for is one it can execute: IK branch continuity through the turn, top-down
grasps reachable at the object's (0.60, 0, 0), and the state machine checking a whole attempt before moving.

Synthetic milk carton (the HOPE milk's 7 x 7 x 19 cm) seen from the arm's side, planned by the real grasp
planner; the arm is the real kinematics/controller (no Zenoh, no twin).
"""

from __future__ import annotations

import asyncio
from dataclasses import replace

import numpy as np
import pytest

from common.api import GraspPlanReply, ViewResult
from common.errors import RemoteError
from common.messages import PointCloud
from services.arm.errors import IKError, TrajectoryError
from services.arm.kinematics import Kinematics, wrist_flip
from services.arm.motion import cartesian_line_path
from services.grasp.planner import plan_grasps
from services.grasp.service import GraspService
from services.orchestrator.config import AcquisitionConfig, TurnMotion
from services.orchestrator.machine import Acquisition, State
from services.orchestrator.motion import check_chord
from services.orchestrator.planning import TurnPoses, turn_sequences
from services.session_store import SessionStore
from tests.grasp.shapes import box, table_plane
from tests.orchestrator.arm_cell import ArmOnlyCell

CENTER = np.array([0.60, 0.0, 0.0])
MILK = (0.07, 0.07, 0.19)
HOME = np.array([0.0, -0.3, -0.9, 0.0, 1.2, 0.0])
MIN_TCP_Z = 0.01  # services/arm/safety.py


def _cameras(center: np.ndarray = CENTER) -> list[np.ndarray]:
    """Three wrist-camera positions on the arm's side of an object at ``center`` (x, y, 0), as the scan poses
    place them."""
    return [center + 0.38 * np.array([-np.cos(np.radians(a)), np.sin(np.radians(a)), 0.0]) + [0, 0, 0.3]
            for a in (-22.0, 0.0, 22.0)]


def _plan(mode: str, yaw_deg: float = 0.0):  # noqa: ANN202
    xyz, normals = box(MILK, n=12000, xy=CENTER[:2], yaw_deg=yaw_deg, view_from=_cameras())
    cfg = replace(GraspService.planner_config(), mode=mode)  # what the grasp service runs with
    return xyz, normals, plan_grasps(xyz, normals, table_plane(), cfg)


def _executable(kin: Kinematics, seq: TurnPoses) -> bool:
    """Kinematically: from the IK branch nearest home (or its other wrist branch) at above_pregrasp, every
    later straight move has a continuous joint path inside the limits, the TCP above the table; a joint-space
    chord (``ChainMove.joint``) has an IK answer near the configuration before it (``motion.check_chord``)."""
    try:
        q_a = kin.ik(seq.above_pregrasp, HOME).q
    except IKError:
        return False
    for q in (q_a, wrist_flip(q_a)):
        if not kin.within_limits(q):
            continue
        try:
            for mv in seq.straight_moves(CENTER):
                if mv.joint:
                    Q = np.array([q, kin.ik(mv.target, q).q])
                    check_chord(mv, Q[0], Q[1])
                else:
                    Q = cartesian_line_path(kin, q, mv.target)
                assert min(kin.fk(p)[2, 3] for p in Q) >= MIN_TCP_Z
                q = Q[-1]
            return True
        except (TrajectoryError, IKError, RemoteError):
            continue
    return False


@pytest.mark.parametrize("yaw_deg", [-30.0, 0.0, 30.0])
def test_frontal_grasp_turns_either_way_on_one_branch(kin, yaw_deg):
    """Either turn direction has an executable frontal grasp, whichever way the carton stands (a session
    keeps its first direction, so both must exist); measured: at 30 degrees only the grasp on the other pair
    of faces turns the mirror way (the first one's wrist would pass joint 5's 90 degrees)."""
    _, _, plan = _plan("frontal", yaw_deg)
    assert plan.grasps, plan.explain()
    seqs = [s for g in plan.to_messages() for s in turn_sequences(g, TurnMotion(), MILK[2])]
    for direction in (1, -1):
        assert any(_executable(kin, s) for s in seqs if s.direction == direction), direction


def test_top_down_grasps_reach_the_object_at_0_60_m_tilted_toward_the_base(kin):
    _, _, plan = _plan("top_down")
    assert plan.grasps, plan.explain()
    grasp = plan.to_messages()[0]
    seqs = [s for s in turn_sequences(grasp, TurnMotion(), MILK[2]) if s.direction == 1]
    # the straight-down approach is out of the arm's reach there; the base-side tilts come first and work
    assert not _executable(kin, next(s for s in seqs if s.name == "grasp"))
    assert seqs[0].name == "grasp_minus45"
    assert _executable(kin, seqs[0])


NEAR_STROKE_BOX = (0.099, 0.143, 0.109)  # m: 9.9 cm along the line from the base, 14.3 across, 10.9 tall


def test_a_top_down_turn_on_the_near_ring_reaches_by_its_low_chains(kin):
    """A 10.9 cm box on the near ring (0.40 m), its only grasp across its 9.9 cm along the line from the base:
    straight down the hand reaches no higher than about 0.17 m there, so no chain with its joint-space moves
    8 cm above the box (0.19 m) is executable, either way round. The same chains 4 cm above it are, both ways,
    and they come after every other chain."""
    center = np.array([0.40, 0.0, 0.0])
    xyz, normals = box(NEAR_STROKE_BOX, n=12000, xy=center[:2], view_from=_cameras(center))
    plan = plan_grasps(xyz, normals, table_plane(), replace(GraspService.planner_config(), mode="top_down"))
    assert plan.grasps, plan.explain()
    seqs = turn_sequences(plan.to_messages()[0], TurnMotion(), NEAR_STROKE_BOX[2])
    high = [s for s in seqs if not s.low_above]
    low = [s for s in seqs if s.low_above]
    assert len(low) == len(high) and seqs[len(high):] == low
    assert all(s.above_pregrasp[2, 3] == pytest.approx(max(NEAR_STROKE_BOX[2] + 0.04, s.pregrasp[2, 3])) for s in low)
    assert not any(_executable(kin, s) for s in high)
    for direction in (1, -1):
        assert any(_executable(kin, s) for s in low if s.direction == direction), direction


@pytest.fixture(scope="module")
def kin() -> Kinematics:
    return Kinematics()


def test_turn_is_checked_in_full_before_the_hand_moves(kin, tmp_path):
    """The case that failed in CI: the session turns the mirror way (-30 degrees). Every executed move
    succeeds, none fails while the object is held, and the machine goes on to the next view."""
    xyz, normals, plan = _plan("auto")
    store = SessionStore(tmp_path)
    store.save_view(ViewResult(view=1, cloud=PointCloud(xyz=xyz.astype(np.float32),
                                                        normals=normals.astype(np.float32)),
                               table=table_plane(), center=CENTER.copy(), height=MILK[2],
                               scan_poses=np.zeros((0, 4, 4))))
    cell = ArmOnlyCell(np.array([0.597, -0.21, 0.198, -0.69, 1.176, 1.119]), kin)  # a scan posture
    acq = Acquisition(cell, store, AcquisitionConfig(views=3))  # type: ignore[arg-type]
    acq.j.update(view=1, state="turn", turns_deg=[0.0, -30.0], turn_direction=-1)
    acq._plan = GraspPlanReply(grasps=plan.to_messages(), rejections={}, explanation=plan.explain(), seconds=0.0)
    nxt = asyncio.run(acq.turn())
    assert nxt == State.SCAN, acq.j.decisions
    assert acq.j.turns_deg[-1] == -60.0
    executed = [m for m in cell.log if not m["dry_run"]]
    assert [m for m in executed if m["error"]] == []
    assert any(m["holding"] for m in executed)
    assert acq.j.counters.grasp_attempts == 1


def test_the_escape_after_a_low_chain_stays_low_where_the_hand_reaches_no_higher(kin):
    """After a low chain on the near ring the hand points down 4 cm above the 10.9 cm box: 8 cm above it, and 9 cm
    back along the approach, are out of the wrist's reach there, so the escape before the next attempt ends 4 cm
    above it, where it already is, instead of going home through the object's box."""
    from services.orchestrator.motion import ArmMotion

    center, height = np.array([0.40, 0.0, 0.0]), NEAR_STROKE_BOX[2]
    T = np.eye(4)
    T[:3, :3] = [[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]]  # x (the approach) down, y radial
    T[:3, 3] = [0.40, 0.0, height + TurnMotion().low_clearance]
    q = kin.ik(T, HOME).q
    cell = ArmOnlyCell(q, kin)
    decisions: list[str] = []
    motion = ArmMotion(cell, TurnMotion(), lambda what, **_: decisions.append(what), lambda *a, **k: None,
                       lambda seq: None)
    asyncio.run(motion.escape(center, height))
    assert "escaping through the object box to home" not in decisions, decisions
    assert np.allclose(cell.arm.state()["T_base_gripper"][:3, 3], T[:3, 3], atol=1e-3)
