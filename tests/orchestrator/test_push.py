"""The poses of a push (``services/orchestrator/push.py``): the closed hand starts low in front of the face that
looks towards the base, at one end of it, and drives that end round the footprint's centre."""

from __future__ import annotations

import numpy as np
import pytest

from services.orchestrator.push import PUSH_HEIGHT, long_side_deg, measured_turn_deg, push_sequences
from tests.grasp import shapes as S


def _box(size: tuple[float, float, float], xy: tuple[float, float], yaw_deg: float) -> np.ndarray:
    center = np.array([*xy, 0.0])
    cams = [center + 0.38 * np.array([-np.cos(np.radians(a)), np.sin(np.radians(a)), 0.0]) + [0, 0, 0.3]
            for a in (-22.0, 0.0, 22.0)]
    xyz, _ = S.box(size, 12000, xy=np.asarray(xy), yaw_deg=yaw_deg, view_from=cams, noise=0.0005)
    return xyz


@pytest.mark.parametrize(("xy", "yaw"), [((0.60, 0.0), 0.0), ((0.55, -0.15), 10.0), ((0.58, 0.12), -80.0)])
def test_a_push_starts_before_the_face_towards_the_base_and_drives_one_end_round(xy, yaw):
    size = (0.099, 0.143, 0.109)
    xyz = _box(size, xy, yaw)
    every = push_sequences(xyz, size[2], 0.08)
    seqs = [s for s in every if "_pitch" not in s.name]  # the level hand's (the pitched ones: below)
    assert every[:len(seqs)] == seqs and len(every) == 2 * len(seqs)  # level first, then the same pitched
    # both ends of each face towards the base (two faces when the box stands turned), turning either way
    assert len(seqs) in (2, 4) and {s.sense for s in seqs} == {1, -1}
    centre = np.array(xy)
    radial = centre / np.linalg.norm(centre)
    for s in seqs:
        approach = s.start[:3, 0]
        assert approach[2] == pytest.approx(0.0) and s.start[:3, 2] @ [0, 0, 1.0] == pytest.approx(1.0)
        assert approach[:2] @ radial > np.cos(np.radians(2.0))  # along the line from the base
        # the pads start clear of the object (their front corners outside its footprint), at the push height,
        # and the hand comes down from above its top
        a = np.radians(yaw)
        rot = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])  # base -> box axes
        for side in (-0.022, 0.0, 0.022):
            corner = s.start[:2, 3] + 0.02 * approach[:2] + side * s.start[:2, 1]
            local = rot @ (corner - centre)
            assert np.any(np.abs(local) > np.array(size[:2]) / 2 + 0.002), (s.name, side)
        assert s.start[2, 3] == pytest.approx(PUSH_HEIGHT)
        assert s.above[2, 3] == pytest.approx(size[2] + 0.08)
        assert all(T[2, 3] == pytest.approx(PUSH_HEIGHT) for T in s.arc)
        # round the centre (the one the seen faces give, within 2 mm of the true one): every chord end as far
        # from it, the hand's orientation unchanged
        tips = [T[:2, 3] + 0.02 * approach[:2] - centre for T in s.arc]
        radii = [float(np.linalg.norm(t)) for t in tips]
        assert np.ptp(radii) < 0.002
        assert all(np.allclose(T[:3, :3], s.start[:3, :3]) for T in s.arc)
        # the first chord drives the contact into the face (along the approach), turning the box s.sense
        assert (tips[1] - tips[0]) @ approach[:2] > 0
        assert np.sign(tips[0][0] * tips[1][1] - tips[0][1] * tips[1][0]) == s.sense
        # out again: back along the approach, then up over the object
        assert s.retreat[-1][2, 3] == pytest.approx(size[2] + 0.08)
    for sense in (1, -1):  # a second push goes on turning it the way the first did
        assert push_sequences(xyz, size[2], 0.08, sense=sense)[0].sense == sense


def test_near_the_base_the_pitched_hand_s_push_is_reached_where_the_level_hand_s_is_not():
    """The 5.4 x 15.8 x 15.3 cm slab standing 0.425 m from the base, its long side along the line from it: the level
    hand's low start 0.32 m out is beyond the wrist (PAPRAS kinematics); pitched 30 degrees down, with its pad tips
    at the same point and height, it is reached, and so is the whole arc."""
    from services.arm.kinematics import IKError, Kinematics

    size = (0.158, 0.054, 0.153)
    seqs = push_sequences(_box(size, (0.425, 0.0), 0.0), size[2], 0.08)
    kin = Kinematics()

    def reached(T: np.ndarray) -> bool:
        try:
            kin.ik(T)
            return True
        except IKError:
            return False

    level = [s for s in seqs if "_pitch" not in s.name]
    pitched = [s for s in seqs if s.name.endswith("_pitch30")]
    assert level and len(pitched) == len(level)
    assert not any(reached(s.start) for s in level)
    for lv, s in zip(level, pitched, strict=True):
        tip = s.start[:3, 3] + 0.02 * s.start[:3, 0]  # the pad tips, half a pad ahead of the TCP
        level_tip = lv.start[:3, 3] + 0.02 * lv.start[:3, 0]
        assert tip == pytest.approx(level_tip, abs=1e-9) and tip[2] == pytest.approx(PUSH_HEIGHT)
        assert s.start[:3, 0] @ [0, 0, 1.0] == pytest.approx(-0.5)  # 30 degrees down
    assert any(all(reached(T) for T in (s.start, *s.arc)) for s in pitched)


def test_a_push_keeps_low_on_a_short_object_and_none_is_planned_on_too_few_points():
    size = (0.099, 0.143, 0.03)
    seqs = push_sequences(_box(size, (0.6, 0.0), 0.0), size[2], 0.08)
    assert all((T[:3, 3] + 0.02 * T[:3, 0])[2] <= 0.5 * size[2] + 1e-9 for s in seqs for T in s.arc)  # pad tips
    assert push_sequences(np.zeros((5, 3)), 0.1, 0.08) == []


def test_a_box_no_pick_reaches_is_pushed_round_and_the_views_restart_where_it_stands(tmp_path):
    """The 9.9 x 14.3 x 10.9 cm box at 0.60 m, graspable only across its 9.9 cm along the line from the base,
    at view 0's last chance (re-scans used up): the push is dry-run whole, run with the hand closed, and the
    views restart at 0 around where the box is expected, the view before it kept aside."""
    import asyncio

    from services.arm.kinematics import Kinematics
    from services.orchestrator.planning import object_box
    from services.orchestrator.push_step import try_push
    from services.orchestrator.states import State
    from tests.orchestrator.test_lay_down import _standing_tall_box

    size = (0.099, 0.143, 0.109)
    cell, acq = _standing_tall_box(Kinematics(), tmp_path, rescans=2, size=size)
    view = acq.store.load_view(0)
    box = object_box(view.center, view.height, view.cloud.xyz, acq.config.turn.object_box_margin)
    asyncio.run(cell.set_object_box(*box))  # as the turn step leaves it: the fingers must be let into it
    assert asyncio.run(try_push(acq, 0, view, box, [])) == State.SCAN
    executed = [m for m in cell.log if not m["dry_run"]]
    assert executed and all(m["error"] is None for m in executed)
    assert sum(m["holding"] for m in executed) >= 12  # the hand closed for the way down, the arc and the way out
    assert not cell.holding  # and open again afterwards
    assert acq.j.counters.pushes == 1 and acq.j.pushes[0]["from_view"] == 0
    assert acq.view == 0 and acq.j.rescans == {} and acq.j.turns_deg == [0.0]
    assert (tmp_path / "view_00_pushed1").is_dir() and not acq.store.has_view(0)
    expected = np.asarray(acq.j.centers["-1"])
    assert 0.03 < expected[0] - 0.60 < 0.08  # the box goes outwards ahead of the pads
    assert "pushed round x1" in acq._recoveries_tried(0)
    # more pushes are allowed up to ``max_pushes``, then none
    acq.j.pushes += [{"push": "push_left_end", "from_view": 0}] * (acq.config.max_pushes - 1)
    acq.j.rescans = {"0": 2}
    assert asyncio.run(try_push(acq, 0, view, box, [])) is None


def test_a_pregrasp_stands_back_until_open_fingers_that_cannot_straddle_the_box_are_clear_of_it():
    """9.9 cm across in a 10.6 cm stroke: the object's collision box (grown 1 cm a side) is wider than the open
    fingers, so a pre-grasp a finger length back leaves them inside it; it stands back until the fingertips are
    out. A box the fingers straddle keeps its pre-grasp."""
    from services.orchestrator.planning import FINGER_TIP, PREGRASP_CLEARANCE, clear_pregrasp

    grasp = np.eye(4)
    grasp[:3, 3] = [0.70, 0.0, 0.05]  # frontal: approach +x, closing along y, 5 cm past the contacts' middle
    pre = grasp.copy()
    pre[0, 3] -= 0.086
    wide = (np.array([0.72, 0.0, 0.06]), np.array([0.163, 0.119, 0.12]))  # 14.3 deep, 9.9 across, +1 cm a side
    rng = np.random.default_rng(0)
    box_xy = np.array([0.72, 0.0]) + rng.uniform(-0.5, 0.5, (2000, 2)) * [0.143, 0.099]
    moved = clear_pregrasp(pre, grasp, wide, box_xy, 0.01, 0.105)
    near_face = 0.72 - 0.163 / 2
    assert moved[0, 3] + FINGER_TIP == pytest.approx(near_face - PREGRASP_CLEARANCE)
    np.testing.assert_array_equal(moved[:3, :3], pre[:3, :3])
    assert moved[1:3, 3] == pytest.approx(pre[1:3, 3])
    narrow = (np.array([0.72, 0.0, 0.06]), np.array([0.163, 0.08, 0.12]))  # 6 cm across: straddled
    slim_xy = np.array([0.72, 0.0]) + rng.uniform(-0.5, 0.5, (2000, 2)) * [0.143, 0.06]
    np.testing.assert_array_equal(clear_pregrasp(pre, grasp, narrow, slim_xy, 0.01, 0.105), pre)
    # a round object's axis-aligned box is wider than it along a diagonal; the object itself decides
    turned = grasp.copy()
    turned[:3, :3] = [[0.7071, -0.7071, 0], [0.7071, 0.7071, 0], [0, 0, 1]]
    can = (np.array([0.72, 0.0, 0.06]), np.array([0.0965, 0.0965, 0.12]))  # 7.65 cm across
    a = rng.uniform(0, 2 * np.pi, 2000)
    can_xy = np.array([0.72, 0.0]) + 0.03825 * np.column_stack([np.cos(a), np.sin(a)])
    np.testing.assert_array_equal(clear_pregrasp(pre, turned, can, can_xy, 0.01, 0.105), pre)


def test_the_pushed_box_is_picked_where_it_now_stands(tmp_path):
    """The 9.9 x 14.3 x 10.9 cm box as two pushes left it (turned 88 degrees, 0.73 m from the base): its pick
    across 9.9 cm was refused on the way down to the pre-grasp (open fingers in its collision box); now the
    turn step picks it (here: brought back to the favoured spot)."""
    import asyncio

    from services.arm.drivers.sim import SimArmDriver
    from services.arm.kinematics import Kinematics
    from services.orchestrator.config import AcquisitionConfig
    from services.orchestrator.machine import Acquisition
    from services.orchestrator.states import State
    from services.session_store import SessionStore
    from tests.orchestrator.test_lay_down import _view
    from tests.orchestrator.test_recovery import PlanningCell, _steps

    size = (0.1431, 0.0991, 0.1087)  # 9.9 cm along y: across the line from the base
    center = np.array([0.7225, 0.1144, 0.0])
    store = SessionStore(tmp_path)
    store.save_view(_view(size, center, 0))
    cell = PlanningCell(np.asarray(SimArmDriver(send=lambda q, o: None).config.initial_q, float), Kinematics())
    acq = Acquisition(cell, store, AcquisitionConfig(views=12))  # type: ignore[arg-type]
    acq.j.update(view=0, state="plan_grasp", centers={"-1": center.tolist(), "0": center.tolist()},
                 heights={"-1": size[2], "0": size[2]})
    states = asyncio.run(_steps(acq, 2))
    assert states[-1] == State.SCAN, acq.j.decisions[-4:]
    assert any(m["holding"] for m in cell.log if not m["dry_run"])
    assert not [d for d in acq.j.decisions if d["what"] == "grasp pose not executable"
                and "hits object" in str(d.get("message"))]


@pytest.mark.parametrize(("before", "after", "sense", "turn"), [(0.0, 50.0, 1, 50.0), (80.0, 130.0, 1, 50.0),
                                                                 (170.0, 35.0, 1, 45.0), (10.0, -35.0, -1, -45.0),
                                                                 (-80.0, 50.0, -1, -50.0)])
def test_a_push_s_turn_is_measured_from_the_footprint_s_long_side_as_partial_views_see_it(before, after, sense, turn):
    size = (0.099, 0.143, 0.109)
    a = long_side_deg(_box(size, (0.60, 0.0), before)[:, :2])
    b = long_side_deg(_box(size, (0.66, 0.03), after)[:, :2])
    assert measured_turn_deg(a, b, sense) == pytest.approx(turn, abs=1.5)


def test_a_push_s_turn_is_not_told_from_a_near_square_footprint_or_beyond_what_a_push_gives():
    assert long_side_deg(_box((0.10, 0.108, 0.109), (0.60, 0.0), 0.0)[:, :2]) is None
    assert measured_turn_deg(30.0, 32.0, 1) is None  # slid, hardly turned
    assert measured_turn_deg(30.0, 70.0, -1) is None  # -140 degrees: more than the pads' whole arc
    assert measured_turn_deg(30.0, 70.0, 1) == pytest.approx(40.0)


def _saved_view(size: tuple[float, float, float], center: np.ndarray, yaw_deg: float, k: int):  # noqa: ANN202
    from common.api import ViewResult
    from common.messages import PointCloud

    c = np.array([center[0], center[1], 0.0])
    cams = [c + 0.38 * np.array([-np.cos(np.radians(a)), np.sin(np.radians(a)), 0.0]) + [0, 0, 0.3]
            for a in (-22.0, 0.0, 22.0)]
    xyz, normals = S.box(size, 8000, xy=c[:2], yaw_deg=yaw_deg, view_from=cams, noise=0.0005)
    return ViewResult(view=k, cloud=PointCloud(xyz=xyz.astype(np.float32), normals=normals.astype(np.float32)),
                      table=S.table_plane(), center=c, height=size[2], scan_poses=np.zeros((0, 4, 4)))


def _pushed_at_view_2(tmp_path):  # noqa: ANN202
    """The 9.9 x 14.3 x 10.9 cm box at view 2 of 12 (views 0-2 taken, re-scans used up), pushed."""
    import asyncio

    from services.arm.kinematics import Kinematics
    from services.orchestrator.planning import object_box
    from services.orchestrator.push_step import try_push
    from tests.orchestrator.test_lay_down import WORKSPACE, _standing_tall_box, _view

    size = (0.099, 0.143, 0.109)
    cell, acq = _standing_tall_box(Kinematics(), tmp_path, rescans=2, size=size)
    for k in (1, 2):
        acq.store.save_view(_view(size, WORKSPACE, k))
    acq.j.update(view=2, turns_deg=[0.0, -30.0, -60.0], turn_direction=-1, rescans={"2": 2},
                 centers={**acq.j.centers, "1": WORKSPACE.tolist(), "2": WORKSPACE.tolist()},
                 heights={**acq.j.heights, "1": size[2], "2": size[2]})
    view = acq.store.load_view(2)
    box = object_box(view.center, view.height, view.cloud.xyz, acq.config.turn.object_box_margin)
    asyncio.run(cell.set_object_box(*box))
    return acq, asyncio.run(try_push(acq, 2, view, box, []))


def test_a_push_after_view_0_is_a_measured_turn_and_the_views_before_it_are_kept(tmp_path):
    """A yaw-tied tall box needs a push each time the wrist's reach runs out: at view 2 the push is followed by
    view 2 scanned again where the push aims the box, under a provisional turn; registered there (here turned 48
    degrees the way the push drives it), its commanded turn becomes the measured one. Views 0 and 1 stay, view
    2's old frames are kept aside."""
    from services.orchestrator.push_step import PROVISIONAL_DEG, measure_push
    from services.orchestrator.states import State

    acq, state = _pushed_at_view_2(tmp_path)
    push = acq.j.pushes[0]
    sense = push["sense"]
    assert sense == acq.j.turn_direction  # the way the views turn it, not back to where views were taken
    assert state == State.SCAN and acq.view == 2 and push["from_view"] == 2 and push["turn_deg"] is None
    assert acq.j.turns_deg == [0.0, -30.0, -60.0 + sense * PROVISIONAL_DEG]
    assert acq.store.has_view(0) and acq.store.has_view(1) and not acq.store.has_view(2)
    assert (tmp_path / "view_02_pushed1").is_dir()
    assert acq.j.counters.pushes == 1 and acq.j.counters.regrasps == 0 and acq.j.counters.repositions == 0
    assert acq.j.rescans["2"] == 0  # a fresh re-scan budget where it now stands
    center = np.asarray(acq.j.centers["2"])
    assert center[:2] == pytest.approx(np.asarray(push["expected_center"])[:2])
    # view 2 registered where it now stands, turned 48 degrees: the view goes on, its turn the measured one
    assert measure_push(acq, 2, _saved_view((0.099, 0.143, 0.109), center, 48.0 * sense, 2)) is None
    assert acq.j.turns_deg[2] == pytest.approx(-60.0 + 48.0 * sense, abs=1.5)
    assert push["turn_deg"] == pytest.approx(48.0 * sense, abs=1.5)
    assert acq.j.regrasps["2"][-1]["commanded_turn_deg"] == pytest.approx(acq.j.turns_deg[2])
    assert measure_push(acq, 2, _saved_view((0.099, 0.143, 0.109), center, 10.0, 2)) is None  # measured once
    assert acq.j.turns_deg[2] == pytest.approx(-60.0 + 48.0 * sense, abs=1.5)


def test_a_push_whose_turn_cannot_be_told_restarts_the_views(tmp_path):
    from services.orchestrator.push_step import measure_push
    from services.orchestrator.states import State

    acq, _ = _pushed_at_view_2(tmp_path)
    (tmp_path / "view_02" / "scan_0").mkdir(parents=True)  # view 2's scans after the push
    center = np.asarray(acq.j.centers["2"])
    square = _saved_view((0.10, 0.105, 0.109), center, 30.0, 2)  # near square from every side
    assert measure_push(acq, 2, square) == State.SCAN
    assert acq.view == 0 and acq.j.turns_deg == [0.0]
    assert all((tmp_path / f"view_0{k}_pushed1_untold").is_dir() for k in range(3))
    assert (tmp_path / "view_02_pushed1").is_dir() and not (tmp_path / "view_02").exists()
    assert any(d["what"].startswith("the push's turn cannot be told") for d in acq.j.decisions)
