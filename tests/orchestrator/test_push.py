"""The poses of a push (``services/orchestrator/push.py``): the closed hand starts low in front of the face that
looks towards the base, at one end of it, and drives that end round the footprint's centre."""

from __future__ import annotations

import numpy as np
import pytest

from services.orchestrator.push import PUSH_HEIGHT, push_sequences
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
    seqs = push_sequences(xyz, size[2], 0.08)
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


def test_a_push_keeps_low_on_a_short_object_and_none_is_planned_on_too_few_points():
    size = (0.099, 0.143, 0.03)
    seqs = push_sequences(_box(size, (0.6, 0.0), 0.0), size[2], 0.08)
    assert all(T[2, 3] <= 0.5 * size[2] + 1e-9 for s in seqs for T in s.arc)
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
    # a second push is allowed, a third is not (``max_pushes``)
    acq.j.pushes.append({"push": "push_left_end", "from_view": 0})
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
