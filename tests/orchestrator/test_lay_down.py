"""Laying a tall object on its side (services/orchestrator/lay_down.py, lay_down_step.py): a tall box that no grasp
turns standing at the workspace centre is picked, tipped 90 degrees about its grasp line and set down lying; the
views restart where it lies and it is turned lying. Real grasp planner, real arm kinematics and controller (no
Zenoh), as in test_recovery.py."""

from __future__ import annotations

import asyncio
from dataclasses import replace

import numpy as np
import pytest

from common.api import ViewResult
from common.messages import PointCloud
from services.arm.drivers.sim import SimArmDriver
from services.arm.kinematics import Kinematics
from services.grasp.planner import plan_grasps
from services.grasp.service import GraspService
from services.orchestrator.config import AcquisitionConfig, RelocationConfig, TurnMotion
from services.orchestrator.lay_down import LAY_DOWN, carry_shifts, lay_down_sequences, stands_tall, whole_object
from services.orchestrator.machine import Acquisition, State
from services.session_store import SessionStore
from tests.grasp.shapes import box, table_plane
from tests.orchestrator.test_recovery import PlanningCell, _cams, _steps

TALL_BOX = (0.0658, 0.109, 0.238)  # m: x, y, height; the generated box that never left view 0
THIN_WIDE_BOX = (0.054, 0.1584, 0.153)  # another that never did: 5.4 cm thin, 15.8 cm across
THIN_TALL_BOX = (0.05, 0.12, 0.22)  # 5 cm thin along the line from the base, 12 cm across, 22 cm tall
WORKSPACE = np.array([0.60, 0.0, 0.0])


@pytest.fixture(scope="module")
def kin() -> Kinematics:
    return Kinematics()


def _view(size: tuple[float, float, float], center: np.ndarray, k: int) -> ViewResult:
    xyz, normals = box(size, 8000, xy=center[:2], view_from=_cams(center), noise=0.0005)
    return ViewResult(view=k, cloud=PointCloud(xyz=xyz.astype(np.float32), normals=normals.astype(np.float32)),
                      table=table_plane(), center=center.copy(), height=size[2], scan_poses=np.zeros((0, 4, 4)))


def test_a_tall_box_is_tall_and_its_lay_down_tips_it_onto_its_side():
    view = _view(TALL_BOX, WORKSPACE, 0)
    assert stands_tall(view.cloud.xyz, view.height)
    assert not stands_tall(_view((0.07, 0.07, 0.08), WORKSPACE, 0).cloud.xyz, 0.08)
    from common.messages import Grasp, Pose

    g = np.eye(4)  # a frontal grasp at mid-height, approached along the line from the base (geometry only)
    g[:3, 3] = [0.60 - 0.0329 + 0.02, 0.0, 0.119]
    pre = g.copy()
    pre[0, 3] -= 0.08
    grasp = Grasp(kind="frontal", contacts=np.array([[0.587, 0.0545, 0.119], [0.587, -0.0545, 0.119]]),
                  width=0.109, poses={"grasp": Pose.from_matrix(g), "pregrasp": Pose.from_matrix(pre)})
    seqs = lay_down_sequences(grasp, view.cloud.xyz, view.center, view.height, TurnMotion(), [np.zeros(3)])
    assert [s.name for s in seqs] == ["grasp_lay_down", "grasp_lay_down_radial",  # and with the pads swapped
                                      "grasp_rolled_lay_down", "grasp_rolled_lay_down_radial"]
    pts = whole_object(view.cloud.xyz, view.center)
    for seq in seqs:
        assert seq.direction == LAY_DOWN
        assert seq.turned[:3, 0] @ [0, 0, -1] > 0.99  # the hand ends above it, pointing down
        assert seq.lying_height == pytest.approx(TALL_BOX[0], abs=0.005)  # its depth along the approach is up now
        for mv in seq.straight_moves(view.center):  # held from the lift to the set-down: above the table
            if mv.phase == "held":
                held = mv.target @ np.linalg.inv(seq.grasp)
                assert float((pts @ held[:3, :3].T + held[:3, 3])[:, 2].min()) > -1e-6, mv.step
        rest = seq.turned @ np.linalg.inv(seq.grasp)
        assert float((pts @ rest[:3, :3].T + rest[:3, 3])[:, 2].min()) == pytest.approx(0.004, abs=1e-6)
        last = seq.straight_moves(view.center)[-1].target[2, 3]
        if seq.arcs:  # backed off along its approach, as far as the pre-grasp stood: no higher (near ring's reach)
            assert last == pytest.approx(seq.retreat[2, 3]) and last > seq.lying_height
        else:
            assert last >= seq.lying_height + 0.05  # backs off up


def test_a_tall_box_picked_across_its_thin_side_is_tipped_through_the_wrist_singularity(kin):
    """The 23.8 cm box turned with its 10.9 cm along the line from the base (the frontal pick across its 6.6 cm
    reaches it at 0.60 m): tipped straight about the grasp line on the near ring, the hand's approach passes the
    forearm's axis (joint 5 at 0) and a straight line's joints 4 and 6 run past their limits; the end, pointing
    down, has one wrist branch within the limits, on the other side of joint 5. Turned first until the approach
    points along the line from the base and tipped in joint-space chords, the lay-down is executable in full,
    and the box lies on its 6.6 cm side, 10.9 cm tall, on the near ring."""
    from tests.orchestrator.test_turn_reach import _executable

    size = (TALL_BOX[1], TALL_BOX[0], TALL_BOX[2])
    view = _view(size, WORKSPACE, 0)
    plan = plan_grasps(view.cloud.xyz, view.cloud.normals, table_plane(),
                       replace(GraspService.planner_config(), mode="frontal"))
    assert plan.grasps, plan.explain()
    seqs = [s for g in plan.to_messages() for s in lay_down_sequences(
        g, view.cloud.xyz, view.center, view.height, TurnMotion(), carry_shifts(view.center, RelocationConfig()))]
    assert not any(_executable(kin, s) for s in seqs if not s.arcs)
    done = [s for s in seqs if s.arcs and _executable(kin, s)]
    assert done, [s.name for s in seqs]
    for seq in done:
        assert "_radial@" in seq.name and any(mv.joint for mv in seq.straight_moves(view.center))
        assert size[0] < seq.lying_height < size[0] + 0.015  # its 10.9 cm up (the far side a mirrored estimate)
        assert np.hypot(*seq.lying_center[:2]) == pytest.approx(RelocationConfig().near_radius, abs=0.02)


def test_a_joint_space_chord_answered_on_another_branch_is_refused():
    """A held chord whose IK answer turns a joint more than a 10-degree chord through the singularity can (the
    answer is another branch: the held object would swing) is refused as the straight line's jump is."""
    from common.errors import RemoteError
    from services.orchestrator.motion import MAX_CHORD_JOINT_STEP, check_chord
    from services.orchestrator.planning import ChainMove

    q = np.zeros(6)
    chord = ChainMove("lay down", np.eye(4), "held", joint=True)
    check_chord(chord, q, q + [0, 0, 0, 0, 0.5, 0])  # joint 5 across its zero: fine
    with pytest.raises(RemoteError) as err:
        check_chord(chord, q, q + [0, 0, 0, MAX_CHORD_JOINT_STEP + 0.1, 0.5, 0])
    assert err.value.code == "line_discontinuous"
    check_chord(ChainMove("lay down", np.eye(4), "held"), q, q + 3.0)  # a straight line is the arm's to check


def _standing_tall_box(kin, tmp_path, rescans: int, size: tuple[float, float, float] = TALL_BOX):  # noqa: ANN001
    store = SessionStore(tmp_path)
    store.save_view(_view(size, WORKSPACE, 0))
    cell = PlanningCell(np.asarray(SimArmDriver(send=lambda q, o: None).config.initial_q, float), kin)
    acq = Acquisition(cell, store, AcquisitionConfig(views=12))  # type: ignore[arg-type]
    acq.j.update(view=0, state="plan_grasp", centers={"-1": WORKSPACE.tolist(), "0": WORKSPACE.tolist()},
                 heights={"-1": size[2], "0": size[2]}, rescans={"0": rescans})
    return cell, acq


def test_a_lay_down_released_restarts_the_views_lying_and_says_so(tmp_path):
    """The record at the release: the standing views are set aside (kept), the views restart at 0 where the
    object lies with a fresh re-scan budget, the journal and the failure summary say it was laid down, and
    later plans treat it as lying."""
    store = SessionStore(tmp_path)
    for k in range(3):
        store.save_view(_view(TALL_BOX, WORKSPACE, k))
    acq = Acquisition(object(), store, AcquisitionConfig(views=12))  # type: ignore[arg-type]
    acq.j.update(view=2, state="turn", turns_deg=[0.0, 30.0, 60.0], turn_direction=1, rescans={"2": 2},
                 centers={"2": WORKSPACE.tolist()}, heights={"2": TALL_BOX[2]},
                 regrasps={"2": [{"strategy": "reposition", "restart": 0}]}, limits={"2": {"dry_run": ["unreachable"]}},
                 laid_down={"state": "planned", "pose": "grasp_lay_down@-0.20,+0.00", "center": [0.4, 0.0, 0.0],
                            "height": 0.066})
    acq._record_release(2, LAY_DOWN, None)
    assert acq.view == 0 and acq.j.turns_deg == [0.0] and acq.j.rescans == {} and acq.state == State.SCAN
    assert all((tmp_path / f"view_0{k}_standing").is_dir() and not store.has_view(k) for k in range(3))
    assert acq.j.laid_down["state"] == "done" and acq.j.laid_down["from_view"] == 2
    assert acq.j.counters.lay_downs == 1 and acq.j.centers == {"-1": [0.4, 0.0, 0.0]}
    assert acq._object_estimate(0)[1] == pytest.approx(0.066)  # the next scan poses: around it lying
    assert "2" not in acq.j.regrasps and "2_standing" in acq.j.regrasps  # the standing evidence kept apart
    assert any(d["what"].startswith("laid on its side") for d in acq.j.decisions)
    assert "laid on its side" in acq._recoveries_tried(0)
    lying = _view((TALL_BOX[2], TALL_BOX[1], TALL_BOX[0]), np.array([0.4, 0.0, 0.0]), 0)
    assert acq._lying(lying.cloud.xyz, lying.height)  # planned frontal and top-down alike, top-down first


def test_a_tall_box_thin_along_the_line_from_the_base_has_an_executable_lay_down(kin):
    """A generated box 5.4 cm thin along the line from the base, 15.8 cm across (wider than the gripper opens),
    15.3 cm tall, at the workspace centre: every grasp across its 5.4 cm closes along the line from the base,
    so no frontal or top-down chain of it reaches (the approach would lean sideways, which the arm never
    reaches); the top-down pick pitched 40 degrees away from the base does, and its lay-down (tip until the
    approach is level, roll the pads level, the object's top toward the base) is executable in full, by the
    arm's own line checks. (That no turn of it is executable, nor the lay-down of any unpitched grasp, the
    state machine's test below finds by dry-running them all.)"""
    from tests.orchestrator.test_turn_reach import _executable

    view = _view(THIN_WIDE_BOX, WORKSPACE, 0)
    plan = plan_grasps(view.cloud.xyz, view.cloud.normals, table_plane(),
                       replace(GraspService.planner_config(), mode="both"))
    grasps = plan.to_messages()
    assert grasps, plan.explain()
    motion = TurnMotion()
    lay_downs = [s for g in grasps for s in lay_down_sequences(g, view.cloud.xyz, view.center, view.height, motion,
                                                                carry_shifts(view.center, RelocationConfig()))]
    seq = next((s for s in sorted(lay_downs, key=lambda s: "_pitch" not in s.name) if _executable(kin, s)), None)
    assert seq is not None, [s.name for s in lay_downs]
    assert "_pitch" in seq.name
    pts = whole_object(view.cloud.xyz, view.center)
    rest = seq.turned @ _held(grasps, seq)  # the object's motion from standing to where it is released
    lying = pts @ rest[:3, :3].T + rest[:3, 3]
    assert float(lying[:, 2].min()) == pytest.approx(0.004, abs=1e-6)  # released just above the table
    assert abs(rest[2, 1]) > 0.99  # its 15.8 cm now stands up: lying on its thin side
    assert float(lying[:, 2].max()) == pytest.approx(THIN_WIDE_BOX[1] + 0.004, abs=0.01)
    # its thin side (object x) lies across the line from the base, within the level approach's yaw
    assert abs(rest[1, 0]) >= np.cos(np.radians(26.0))
    assert np.linalg.norm(seq.lying_center[:2] - WORKSPACE[:2]) < 0.03  # centred where it stood


def _held(grasps, seq):  # noqa: ANN001, ANN202
    """Inverse of the unpitched grasp pose of the pitched pick ``seq`` (the pads swapped for a rolled one): once
    seated on the pads the object is held as that grasp holds it."""
    from services.orchestrator.lay_down import ROLL_HALF

    g = next(g for g in grasps if any(np.allclose(seq.grasp, p.matrix() @ f) for p in g.poses.values()
                                      for f in (np.eye(4), ROLL_HALF)))
    seated = g.poses["grasp"].matrix()
    return np.linalg.inv(seated @ ROLL_HALF if "_rolled" in seq.name else seated)


def test_a_slab_as_wide_as_it_is_tall_is_not_laid_down_on_its_other_edge(kin, tmp_path):
    """The 5.4 x 15.8 x 15.3 cm slab: its pitched lay-down is executable, but would leave it lying 15.8 cm
    tall, no lower than it stands, so it is not tried (measured in a whole MuJoCo acquisition: laid down, it
    was as far out of reach lying)."""
    cell, acq = _standing_tall_box(kin, tmp_path, rescans=2, size=THIN_WIDE_BOX)
    view = acq.store.load_view(0)
    from services.orchestrator.lay_down_step import try_lay_down

    assert asyncio.run(try_lay_down(acq, 0, view, (np.zeros(3), np.zeros(3)), [])) is None
    last = acq.j.decisions[-1]
    assert last["what"] == "no lay-down executable" and last["checks"] == 0 and last["not_lower"] > 0
    assert not [m for m in cell.log if not m["dry_run"]]  # nothing moved


@pytest.mark.slow  # every standing chain is dry-run first (as in a real acquisition): a few minutes, loaded
def test_a_tall_box_thin_along_the_line_from_the_base_is_laid_down_and_the_views_restart(kin, tmp_path):
    """A 22 cm box thin along the line from the base, 12 cm across, in the state machine at the view's last
    chance: no turn, no reposition is executable, so it is laid down by the pitched pick (12 cm tall lying),
    and the views restart at 0 where it lies (such a box stopped "limit: reach" before)."""
    _, acq = _standing_tall_box(kin, tmp_path, rescans=2, size=THIN_TALL_BOX)
    states = asyncio.run(_steps(acq, 8))
    assert states[-1] == State.SCAN, acq.j.decisions[-5:]
    assert acq.j.laid_down["state"] == "done" and "_pitch" in acq.j.laid_down["pose"]
    assert acq.view == 0 and acq.j.counters.lay_downs == 1
    assert "laid on its side" in acq._recoveries_tried(0)


def test_a_lay_down_finished_before_a_restart_is_recorded_not_repeated(tmp_path):
    from tests.orchestrator.test_reposition import _ReleasedCell

    store = SessionStore(tmp_path)
    store.save_view(_view(TALL_BOX, WORKSPACE, 0))
    release = np.eye(4)
    release[:3, 3] = [0.4, 0.0, 0.15]
    cell = _ReleasedCell(release)
    acq = Acquisition(cell, store, AcquisitionConfig(views=12))  # type: ignore[arg-type]
    acq.j.update(view=0, state="turn", rescans={"0": 2}, centers={"0": WORKSPACE.tolist()},
                 heights={"0": TALL_BOX[2]},
                 laid_down={"state": "planned", "pose": "grasp_lay_down@-0.20,+0.00", "center": [0.4, 0.0, 0.0],
                            "height": 0.066},
                 turn_intent={"view": 0, "phase": "holding", "direction": LAY_DOWN, "opening": 0.1, "shift": None,
                              "release_T": release.tolist(), "center": WORKSPACE.tolist(), "height": TALL_BOX[2]})
    asyncio.run(acq._recover_turn())
    assert cell.openings == [0.1]  # released where it was set down, never moved again
    assert acq.view == 0 and acq.state == State.SCAN and acq.j.turn_intent is None
    assert acq.j.laid_down["state"] == "done" and (tmp_path / "view_00_standing").is_dir()
