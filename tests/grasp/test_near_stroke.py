"""A grasp near the gripper's stroke (a 9.9 cm box in a 10.6 cm stroke) is planned on a level grasp line and opened
to the whole stroke, so that its pads fit beside the box although the camera puts the box a few millimetres off.

The pads are checked by the twin's own test of a grasp (``services/sim/gripper.GraspChecker``) on the true box."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from common.stroke import STROKE, near_stroke
from services.grasp.config import GraspPlannerConfig
from services.grasp.near_stroke import level_contacts
from services.grasp.planner import plan_grasps
from services.orchestrator.motion import FULL_OPENING, PITCHED_OPENING, pick_opening
from services.sim.gripper import GraspChecker
from tests.grasp import shapes as S

CENTER = np.array([0.60, 0.0])
UP = np.array([0.0, 0.0, 1.0])
#: the box of the completion bench that no pick held: 14.3 cm deep along the line from the base, 9.9 cm across
NEAR_STROKE_BOX = (0.1431, 0.0991, 0.1087)


def _cams() -> list[np.ndarray]:
    c = np.array([*CENTER, 0.0])
    return [c + 0.38 * np.array([-np.cos(np.radians(a)), np.sin(np.radians(a)), 0.0]) + [0, 0, 0.3]
            for a in (-22.0, 0.0, 22.0)]


def _plan(size: tuple[float, float, float], seed: int, mode: str = "frontal"):  # noqa: ANN202
    xyz, n = S.box(size, 12000, xy=CENTER, view_from=_cams(), noise=0.001, seed=seed)
    return plan_grasps(xyz, n, S.table_plane(), GraspPlannerConfig(mode=mode))


def _checker(size: tuple[float, float, float]) -> tuple[GraspChecker, np.ndarray]:
    """The twin's grasp test on the true box (its frame: centred on the footprint, z up from the table)."""
    mesh = o3d.geometry.TriangleMesh.create_box(*size)
    mesh.translate([-0.5 * size[0], -0.5 * size[1], 0.0])
    mesh.compute_triangle_normals()
    pcd = mesh.sample_points_uniformly(60000, use_triangle_normal=True)
    checker = GraspChecker(np.asarray(mesh.vertices), np.asarray(mesh.triangles), np.asarray(pcd.points),
                           np.asarray(pcd.normals), float(mesh.get_surface_area()))
    return checker, np.asarray(mesh.vertices)


def test_two_contacts_at_different_heights_are_levelled_to_their_mean_height():
    p1, p2 = np.array([0.6, 0.05, 0.054]), np.array([0.6, -0.047, 0.046])
    a, b = level_contacts(p1, p2, UP)
    assert a[2] == pytest.approx(0.05) and b[2] == pytest.approx(0.05)
    assert a[:2] == pytest.approx(p1[:2]) and b[:2] == pytest.approx(p2[:2])


@pytest.mark.parametrize("mode", ["frontal", "top_down"])
def test_a_grasp_near_the_stroke_closes_along_a_level_line(mode):
    plan = _plan(NEAR_STROKE_BOX, seed=3, mode=mode)
    assert plan.grasps, plan.explain()
    for g in plan.grasps:
        assert near_stroke(g.width)
        assert abs(g.poses["grasp"][:3, 1] @ UP) < 1e-9  # the closing axis lies along the table
        assert g.contacts[0][2] == pytest.approx(g.contacts[1][2])


def test_a_grasp_with_room_to_spare_keeps_the_line_through_its_contacts():
    plan = _plan((0.1431, 0.06, 0.1087), seed=3)
    assert plan.grasps, plan.explain()
    g = plan.grasps[0]
    assert not near_stroke(g.width)
    line = (g.contacts[0] - g.contacts[1]) / np.linalg.norm(g.contacts[0] - g.contacts[1])
    assert g.poses["grasp"][:3, 1] == pytest.approx(line, abs=1e-9)


def test_a_near_stroke_grasp_opens_the_whole_stroke_and_others_keep_their_opening():
    assert pick_opening(0.0991, 0.04, False) == STROKE
    assert pick_opening(0.09, 0.04, False) == FULL_OPENING
    assert pick_opening(0.06, 0.04, False) == pytest.approx(0.10)
    assert pick_opening(0.0991, 0.04, True) == FULL_OPENING  # a pitched pick keeps its own rule
    assert pick_opening(0.05, 0.04, True) == PITCHED_OPENING


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
@pytest.mark.parametrize("located_off_mm", [-2.5, 2.5])
def test_the_pads_fit_beside_a_near_stroke_box_the_camera_puts_off_by_two_and_a_half_millimetres(seed, located_off_mm):
    """The box stands ``located_off_mm`` across the grasp from where its scan puts it (the camera's location error on
    the twin's robot profile); every frontal grasp planned on the scan, opened as the orchestrator opens it, must
    fit its pads beside the true box."""
    plan = _plan(NEAR_STROKE_BOX, seed=seed)
    checker, _ = _checker(NEAR_STROKE_BOX)
    T_base_object = np.eye(4)
    T_base_object[:3, 3] = [CENTER[0], CENTER[1] + located_off_mm * 1e-3, 0.0]
    assert plan.grasps, plan.explain()
    for g in plan.grasps:
        T = g.poses["grasp"]
        opening = pick_opening(g.width, 0.04, False)
        outcome, _ = checker.evaluate(np.linalg.inv(T_base_object) @ T, T, opening, 0.0)
        assert outcome.reason not in ("pad_collides_with_object", "too_wide"), outcome.message


@pytest.mark.parametrize("mode", ["frontal", "top_down"])
@pytest.mark.parametrize("width", [0.107, 0.109])
def test_a_box_a_little_wider_than_the_stroke_gets_no_grasp_across_it(mode, width):
    """Two points of the cloud a little inside the faces of a box wider than the stroke pass the pair's width test
    (10.5-10.6 cm apart on a 10.7-10.9 cm box); settled on their faces they lie farther apart than the stroke."""
    for seed in (1, 2, 3):
        plan = _plan((0.1431, width, 0.1087), seed=seed, mode=mode)
        assert plan.grasps == [], [round(g.width, 4) for g in plan.grasps]
        assert plan.rejections.counts.get("too_wide", 0) > 0


def test_a_pair_near_the_stroke_across_a_turned_box_wider_than_the_stroke_is_too_wide():
    """A pair 10.5 cm long across a 6.6 x 10.9 cm box turned 30 degrees (one contact on an edge): the box spans more
    than the stroke where the pads close, so the grasp is too wide; the same pair square across a 9.3 cm box is kept."""
    from services.grasp.planner import _near_stroke_rejected
    from services.grasp.poses import frontal_rotation
    from services.grasp.ranking import RankedPair
    from services.grasp.result import Rejections
    from services.grasp.service import GraspService

    cfg = GraspService.planner_config()  # as the service plans: the TCP 1 cm past the contacts
    p1, p2 = np.array([0.6, 0.0525, 0.1]), np.array([0.6, -0.0525, 0.1])
    R, _ = frontal_rotation(p1, p2, UP, np.zeros(3))
    pair = RankedPair(i=0, j=1, rank=9.0, metrics={"width": 0.105}, n_i=np.array([0.94, 0.342, 0.0]),
                      n_j=np.array([0.0, -1.0, 0.0]))
    wide, _ = S.box((0.066, 0.109, 0.238), 12000, xy=CENTER, yaw_deg=30.0, view_from=_cams(), noise=0.001)
    narrow, _ = S.box((0.069, 0.093, 0.171), 12000, xy=CENTER, view_from=_cams(), noise=0.001)
    rej = Rejections()
    assert _near_stroke_rejected(p1, p2, R, wide, cfg, rej, "frontal", "y", pair)
    assert rej.counts == {"too_wide": 1}
    assert not _near_stroke_rejected(p1, p2, R, narrow, cfg, rej, "frontal", "y", pair)
    far = RankedPair(i=0, j=1, rank=9.0, metrics={"width": 0.06}, n_i=pair.n_i, n_j=pair.n_j)
    assert not _near_stroke_rejected(p1, p2, R, wide, cfg, rej, "frontal", "y", far)  # not near the stroke


def test_a_near_stroke_pair_from_an_edge_keeps_its_two_points():
    """Settling contacts on their faces is for two faces: a contact on an edge (its normal 70 degrees off the line)
    keeps the pair's own points, which moved the pads of a 9.96 cm edge pair into a 9.3 cm box when settled."""
    from services.grasp.near_stroke import near_stroke_contacts

    xyz = np.array([[0.6, 0.0498, 0.104], [0.6, -0.0498, 0.096], [0.605, 0.0498, 0.1], [0.6, -0.0502, 0.1],
                    [0.598, -0.0497, 0.102], [0.603, -0.0501, 0.098]])
    edge = np.array([[0.94, 0.342, 0.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, -1.0, 0.0],
                     [0.0, -1.0, 0.0]])
    p1, p2 = near_stroke_contacts(xyz, edge, 0, 1, UP, STROKE, 0.005)
    assert p1 == pytest.approx(xyz[0]) and p2 == pytest.approx(xyz[1])
    square = edge.copy()
    square[0] = [0.0, 1.0, 0.0]
    p1, p2 = near_stroke_contacts(xyz, square, 0, 1, UP, STROKE, 0.005)
    assert p1[2] == pytest.approx(p2[2])  # two faces: levelled


@pytest.mark.parametrize("line_deg", [0.0, 25.0, 40.0])
def test_a_pair_whose_open_pads_meet_the_box_is_too_wide(line_deg):
    """The 9.9 x 14.3 cm box seen from the arm's side, a top-down pair through its middle: across its 9.9 cm
    (``line_deg`` 0) the pads opened the whole stroke clear it; along a line turned 25 or 40 degrees the seen box
    spans 10.9 or 12.9 cm between where the pads stand, and they meet it, however short the pair (9.4 cm, one
    contact where the view did not reach, in a whole run), so the pair is rejected as too wide. A pair on an edge
    is not: closing on it turns the box until its faces lie on the pads."""
    from services.grasp.planner import Rejections, _open_pads_hit
    from services.grasp.poses import top_down_rotation

    size = (NEAR_STROKE_BOX[1], NEAR_STROKE_BOX[0], NEAR_STROKE_BOX[2])  # 9.9 cm along the line from the base
    xyz, _ = S.box(size, 12000, xy=CENTER, view_from=_cams(), noise=0.001, seed=0)
    a = np.radians(line_deg)
    half = 0.5 * 0.094 * np.array([np.cos(a), np.sin(a), 0.0])
    mid = np.array([*CENTER, 0.08])
    p1, p2 = mid + half, mid - half
    cfg = GraspPlannerConfig(mode="top_down")
    R, _ = top_down_rotation(p1, p2, UP, np.asarray(cfg.approach_origin, float))
    line = (p1 - p2) / np.linalg.norm(p1 - p2)
    square, edge = _Pair(line, -line), _Pair(line, np.array([-line[1], line[0], 0.0]))
    rej = Rejections()
    hit = _open_pads_hit(p1, p2, R, xyz, cfg, rej, "top_down", "y", square)
    assert hit == (line_deg > 0.0)
    assert ("too_wide" in rej) == hit
    # a pair closing on an edge is left to turn the box in the hand
    assert not _open_pads_hit(p1, p2, R, xyz, cfg, Rejections(), "top_down", "y", edge)


class _Pair:
    """What the test reads of a ranked pair: its contact normals (one face mirrored in where the view did not
    reach carries the mirror of the seen one's: both along the line) and its rank."""

    rank = 9.0

    def __init__(self, n_i: np.ndarray, n_j: np.ndarray):
        self.n_i, self.n_j = n_i, n_j
