"""Top-down grasps on a box whose grasp line runs along the line from the arm's base also come pitched about the
gripper's z through the TCP (services/grasp/pitch.py): the approach leans away from the base by the pitch, the
lean the arm reaches at 0.45-0.60 m. Not across that line (the pitch would lean sideways) and not on a round
section (rolled there instead)."""

from __future__ import annotations

import numpy as np
import pytest

from services.grasp.config import GraspPlannerConfig
from services.grasp.planner import plan_grasps
from tests.grasp import shapes as S

CENTER = np.array([0.60, 0.0])
DOWN = np.array([0.0, 0.0, -1.0])
OUT = np.array([1.0, 0.0, 0.0])  # away from the base at CENTER


def _cams() -> list[np.ndarray]:
    c = np.array([*CENTER, 0.0])
    return [c + 0.38 * np.array([-np.cos(np.radians(a)), np.sin(np.radians(a)), 0.0]) + [0, 0, 0.3]
            for a in (-22.0, 0.0, 22.0)]


def _top_down(size: tuple[float, float, float]):  # noqa: ANN202
    xyz, n = S.box(size, 12000, xy=CENTER, view_from=_cams(), noise=0.0005)
    return plan_grasps(xyz, n, S.table_plane(), GraspPlannerConfig(mode="top_down"))


def test_a_box_thin_along_the_line_from_the_base_gets_grasps_leaning_away_from_it():
    plan = _top_down((0.054, 0.1584, 0.153))  # 5.4 cm along the line from the base, wider than the stroke across
    assert any("grasp_pitch35" in g.poses for g in plan.grasps), plan.explain()
    for g in plan.grasps:
        T = g.poses["grasp"]
        assert abs(T[:3, 1] @ OUT) > 0.99  # the pads close along the line from the base
        mid = np.asarray(g.contacts).mean(axis=0)
        for angle in (a for a in (35, 40) if f"grasp_pitch{a}" in g.poses):
            P, pre = g.poses[f"grasp_pitch{angle}"], g.poses[f"pregrasp_pitch{angle}"]
            x = P[:3, 0]
            assert x @ OUT == pytest.approx(np.sin(np.radians(angle)), abs=1e-3)  # leaning away from the base
            assert x @ DOWN == pytest.approx(np.cos(np.radians(angle)), abs=1e-3)
            # pitched about the contacts' midpoint: it keeps its place and its offset along the approach
            assert (P[:3, 3] - mid) @ x == pytest.approx((T[:3, 3] - mid) @ T[:3, 0], abs=1e-9)
            np.testing.assert_allclose(np.cross(P[:3, 3] - mid, x), 0.0, atol=1e-9)
            np.testing.assert_allclose(P[:3, 2], T[:3, 2], atol=1e-12)  # about the gripper's z
            np.testing.assert_allclose(pre[:3, :3], P[:3, :3], atol=1e-12)
            np.testing.assert_allclose(P[:3, 3] - pre[:3, 3], 0.086 * x, atol=1e-9)  # backed off along it
            assert f"turn_pitch{angle}" not in g.poses  # seated on the pads it is held as the plain grasp holds it


def test_no_pitch_where_the_open_pads_would_cut_the_box():
    """6.6 cm thin: tilted 40 degrees against its faces, the 4 cm pads need 8.6 + 3.4 cm of opening, the gripper
    opens 10.6 cm; at 35 degrees the pads pulled back as they open still cut it."""
    plan = _top_down((0.0658, 0.109, 0.238))
    assert plan.grasps, plan.explain()
    names = {name for g in plan.grasps for name in g.poses}
    assert not any("_pitch" in name for name in names)


def test_no_pitch_across_the_line_from_the_base_nor_on_a_round_section():
    plan = _top_down((0.109, 0.0658, 0.238))  # the same box turned: thin across the line from the base
    assert plan.grasps, plan.explain()
    assert not any("_pitch" in name for g in plan.grasps for name in g.poses)
    xyz, n = S.cylinder(0.033, 0.19, 12000, lying_along=np.array([1.0, 0.0, 0.0]), xy=CENTER, view_from=_cams())
    lying = plan_grasps(xyz, n, S.table_plane(), GraspPlannerConfig(mode="top_down"))
    assert lying.grasps, lying.explain()
    assert not any("_pitch" in name for g in lying.grasps for name in g.poses)
