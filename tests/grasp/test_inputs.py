"""Bad input and bad configuration give typed errors with stable codes, never a crash."""

from __future__ import annotations

import numpy as np
import pytest

from common.errors import InvalidRequest, ObjscanError
from common.messages import Plane, PointCloud
from services.grasp import GraspConfigError, GraspInputError, GraspPlannerConfig, GripperConfig, plan_grasps
from services.grasp.planner import plan_grasps_for_cloud
from tests.grasp import shapes as S


@pytest.fixture(scope="module")
def can():
    return S.soup_can(n=3000, view_from=S.scan_cameras())


def _code(excinfo) -> str:
    return excinfo.value.code


def test_empty_cloud(can):
    with pytest.raises(GraspInputError) as e:
        plan_grasps(np.zeros((0, 3)), np.zeros((0, 3)), S.table_plane())
    assert _code(e) == "empty_cloud"
    assert isinstance(e.value, InvalidRequest) and isinstance(e.value, ObjscanError)


def test_too_few_points(can):
    p, n = can
    with pytest.raises(GraspInputError) as e:
        plan_grasps(p[:5], n[:5], S.table_plane())
    assert _code(e) == "empty_cloud" and e.value.detail["n"] == 5


@pytest.mark.parametrize("where", ["xyz", "normals"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_values(can, where, bad):
    p, n = (a.copy() for a in can)
    (p if where == "xyz" else n)[17, 1] = bad
    with pytest.raises(GraspInputError) as e:
        plan_grasps(p, n, S.table_plane())
    assert _code(e) == "non_finite" and e.value.detail["first"] == 17


def test_missing_normals(can):
    with pytest.raises(GraspInputError) as e:
        plan_grasps(can[0], None, S.table_plane())
    assert _code(e) == "missing_normals"
    with pytest.raises(GraspInputError) as e:
        plan_grasps_for_cloud(PointCloud(xyz=can[0].astype(np.float32)), S.table_plane())
    assert _code(e) == "missing_normals"


@pytest.mark.parametrize("xyz_shape,n_shape", [((100, 2), (100, 2)), ((100,), (100,)), ((100, 3), (99, 3)),
                                               ((100, 3), (100, 4))])
def test_wrong_shapes(xyz_shape, n_shape):
    with pytest.raises(GraspInputError) as e:
        plan_grasps(np.ones(xyz_shape), np.ones(n_shape), S.table_plane())
    assert _code(e) == "bad_shape"


def test_non_numeric_cloud():
    with pytest.raises(GraspInputError) as e:
        plan_grasps([["a", "b", "c"]] * 20, np.ones((20, 3)), S.table_plane())
    assert _code(e) == "bad_shape"


def test_zero_normals(can):
    p, n = (a.copy() for a in can)
    n[3] = 0.0
    with pytest.raises(GraspInputError) as e:
        plan_grasps(p, n, S.table_plane())
    assert _code(e) == "zero_normals"


def test_bad_table(can):
    p, n = can
    for table in (Plane(normal=np.zeros(3), offset=0.0, center=np.zeros(3)),
                  Plane(normal=np.array([0.0, 0.0, np.nan]), offset=0.0, center=np.zeros(3)),
                  object()):
        with pytest.raises(GraspInputError) as e:
            plan_grasps(p, n, table)
        assert _code(e) == "bad_table"


def test_frame_mismatch(can):
    cloud = PointCloud(xyz=can[0].astype(np.float32), normals=can[1].astype(np.float32), frame="camera")
    with pytest.raises(GraspInputError) as e:
        plan_grasps_for_cloud(cloud, S.table_plane())
    assert _code(e) == "frame_mismatch"


def test_wire_cloud_plans_like_arrays(can):
    cloud = PointCloud(xyz=can[0].astype(np.float32), normals=can[1].astype(np.float32))
    plan = plan_grasps_for_cloud(cloud, S.table_plane())
    assert plan.grasps


def test_unnormalised_normals_are_accepted(can):
    p, n = can
    a = plan_grasps(p, n, S.table_plane())
    b = plan_grasps(p, 3.0 * n, S.table_plane())
    assert [g.rank for g in a.grasps] == pytest.approx([g.rank for g in b.grasps])


@pytest.mark.parametrize("kwargs", [{"slice_thickness": 0.0}, {"slice_thickness": -0.007}, {"w1": float("nan")},
                                    {"mode": "sideways"}, {"max_contact_angle_deg": 0.0},
                                    {"max_grasp_line_tilt_deg": 95.0}, {"pregrasp_distance": -1.0},
                                    {"table_clearance": -0.001}, {"region_voxel": float("inf")}])
def test_bad_planner_config(kwargs):
    with pytest.raises(GraspConfigError) as e:
        GraspPlannerConfig(**kwargs)
    assert _code(e) == "bad_grasp_config"


@pytest.mark.parametrize("kwargs", [{"max_opening": 0.0}, {"pad_width": -0.01}, {"min_opening": 0.2},
                                    {"finger_length": float("nan")}])
def test_bad_gripper_config(kwargs):
    with pytest.raises(GraspConfigError):
        GripperConfig(**kwargs)


def test_another_gripper_is_a_config_change():
    """A narrower gripper (max opening 5 cm) cannot take the 6.8 cm can: too_wide, no grasp."""
    p, n = S.soup_can(view_from=S.scan_cameras())
    narrow = GraspPlannerConfig(gripper=GripperConfig(name="narrow", max_opening=0.05), mode="frontal")
    plan = plan_grasps(p, n, S.table_plane(), narrow)
    assert not plan.grasps and "too_wide" in plan.rejections
    assert plan_grasps(p, n, S.table_plane(), GraspPlannerConfig(mode="frontal")).grasps
