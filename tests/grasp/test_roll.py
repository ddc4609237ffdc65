"""Top-down grasps on a round body lying across the line from the arm's base also come rolled about its axis
(services/grasp/roll.py): the pads stay on the section, and the "minus" roll leans the approach toward the base.
Never on a box."""

from __future__ import annotations

import numpy as np

from services.grasp.config import GraspPlannerConfig
from services.grasp.planner import plan_grasps
from services.grasp.roll import round_section
from tests.grasp import shapes as S

CENTER = np.array([0.60, 0.0])
UP = np.array([0.0, 0.0, 1.0])


def _cams() -> list[np.ndarray]:
    c = np.array([*CENTER, 0.0])
    return [c + 0.38 * np.array([-np.cos(np.radians(a)), np.sin(np.radians(a)), 0.0]) + [0, 0, 0.3]
            for a in (-22.0, 0.0, 22.0)]


def test_a_lying_bottle_section_is_round_and_a_box_is_not():
    xyz, _ = S.cylinder(0.033, 0.19, 12000, lying_along=np.array([0.0, 1.0, 0.0]), xy=CENTER, view_from=_cams())
    found = round_section(xyz, np.array([0.60, 0.0, 0.045]), np.array([0.0, 1.0, 0.0]), UP)
    assert found is not None
    centre, r = found
    np.testing.assert_allclose(centre, [0.60, 0.0, 0.033], atol=0.002)
    assert abs(r - 0.033) < 0.002
    box, _ = S.box((0.066, 0.19, 0.066), 12000, xy=CENTER, view_from=_cams())
    assert round_section(box, np.array([0.60, 0.0, 0.045]), np.array([0.0, 1.0, 0.0]), UP) is None


def test_rolled_grasps_keep_the_pads_on_the_section_and_lean_toward_the_base():
    xyz, n = S.cylinder(0.033, 0.19, 12000, lying_along=np.array([0.0, 1.0, 0.0]), xy=CENTER, view_from=_cams(),
                        noise=0.0005)
    plan = plan_grasps(xyz, n, S.table_plane(), GraspPlannerConfig(mode="top_down"))
    rolled = [g for g in plan.grasps if "grasp_rollminus30" in g.poses]
    assert rolled, plan.explain()
    g = rolled[0]
    axis_point = np.array([0.60, 0.0, 0.033])
    reach = np.hypot(*(g.poses["grasp"][:3, 3] - axis_point)[[0, 2]])
    for name in ("grasp", "grasp_rollminus30", "grasp_rollplus45"):
        T = g.poses[name]
        rel = T[:3, 3] - axis_point
        assert abs(np.hypot(rel[0], rel[2]) - reach) < 0.0015  # turned about the (fitted) axis
        assert abs(T[:3, 2] @ np.array([0.0, 1.0, 0.0])) > 0.99  # the gripper's z stays along the lying axis
    # the approach (x) points into the object: rolled "minus", it points away from the base (+x) by ~30 deg more
    x0, minus, plus = (g.poses[k][:3, 0] for k in ("grasp", "grasp_rollminus30", "grasp_rollplus30"))
    assert np.degrees(np.arcsin(minus[0])) - np.degrees(np.arcsin(x0[0])) > 25.0
    assert np.degrees(np.arcsin(x0[0])) - np.degrees(np.arcsin(plus[0])) > 25.0
    standing, sn = S.cylinder(0.033, 0.12, 12000, xy=CENTER, view_from=_cams(), noise=0.0005)
    plan = plan_grasps(standing, sn, S.table_plane(), GraspPlannerConfig(mode="top_down"))
    assert plan.grasps and not any(k.startswith("grasp_roll") for g in plan.grasps for k in g.poses)
