"""The world: grasp soundness and its reasons, a held object following the gripper, set-down upright on
the table, believed vs true camera poses, state and reset."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from common.geometry import make_transform, rotation_about_axis, rotation_angle_deg, transform_error
from common.messages import d435_intrinsics
from services.sim.catalogue import load_object
from services.sim.errors import SimInputError
from services.sim.gripper import GripperSpec
from services.sim.world import DEFAULT_OBJECT_XY, SimStateError, World, default_object_pose, yaw_of
from tests.sim.meshes import write_box_ply

OBJ_XY = np.array(DEFAULT_OBJECT_XY)
FRONT_X = OBJ_XY[0] - 0.03  # the 60 mm box's face towards the robot
SMALL = d435_intrinsics(320, 240)


@pytest.fixture
def box(tmp_path):
    """A 60 x 60 x 150 mm box (a carton), loaded once per test."""
    return load_object(str(write_box_ply(tmp_path, (0.06, 0.06, 0.15), name="carton")))


def frontal(x: float = OBJ_XY[0], y: float = 0.0, z: float = 0.075, yaw_deg: float = 0.0) -> np.ndarray:
    """Gripper approaching along base +x (x = approach, y = across the fingers, z = up)."""
    return make_transform(rotation_about_axis([0, 0, 1], np.radians(yaw_deg)), [x, y, z])


def test_grasp_around_the_object_succeeds_and_reports_its_width(box):
    w = World(box)
    out = w.close_gripper(frontal(), 0.0)
    assert out.success and out.reason == "ok"
    assert out.width == pytest.approx(0.06, abs=0.0015)
    assert w.attached and w.gripper_opening == pytest.approx(out.width)


def test_off_centre_grasp_pushes_the_object_onto_the_gripper_axis(box):
    w = World(box)
    assert w.close_gripper(frontal(y=0.012), 0.0).success
    assert w.true_object_pose()[1, 3] == pytest.approx(0.012, abs=0.001)


def test_pads_retract_as_they_open():
    spec = GripperSpec()
    assert spec.pad_center_x(0.0) == 0.0  # the TCP is between the pads fully closed
    assert spec.pad_center_x(0.073) == pytest.approx(-0.0103)
    assert spec.pad_center_x(0.106) < spec.pad_center_x(0.06) < spec.pad_center_x(0.02) < 0


def test_a_grasp_too_shallow_for_the_retracted_pads_fails(box):
    """With the fingers 60 mm apart the pads sit 6.5 mm behind the TCP: a TCP just 5 mm inside the box
    front leaves the pads almost entirely in front of it."""
    w = World(box)
    out = w.close_gripper(frontal(x=FRONT_X + 0.005 - 0.02), 0.0)  # pad tips end 1.5 mm - 6.5 mm short
    assert (out.success, out.reason) == (False, "nothing_between_pads")


@pytest.mark.parametrize("pose,opening,reason", [
    (frontal(y=0.2), None, "nothing_between_pads"),  # beside the object
    (frontal(x=OBJ_XY[0] + 0.14), None, "nothing_between_pads"),  # past it, fingers in the air
    (frontal(z=0.005), None, "pad_hits_table"),  # pads below the table top
    (frontal(), 0.04, "pad_collides_with_object"),  # opened narrower than the object
    (frontal(y=0.05), None, "pad_collides_with_object"),  # one pad inside the object
    # pad tips reach 0.3 mm past the box's front face once closed on its 60 mm
    (frontal(x=FRONT_X - GripperSpec().pad_center_x(0.06) - GripperSpec().pad_length / 2 + 0.0003), None,
     "insufficient_contact"),
])
def test_unsound_grasps_fail_and_say_why(box, pose, opening, reason):
    w = World(box)
    if opening is not None:
        w.set_gripper_opening(opening)
    before = w.true_object_pose()
    out = w.close_gripper(pose, 0.0)
    assert not out.success
    assert out.reason == reason, out.message
    assert out.message
    assert not w.attached
    np.testing.assert_array_equal(w.true_object_pose(), before)  # a failed grasp leaves it standing


def test_object_wider_than_the_gripper(tmp_path):
    wide = load_object(str(write_box_ply(tmp_path, (0.06, 0.14, 0.1), name="wide")))
    out = World(wide).close_gripper(frontal(z=0.05), 0.0)
    assert (out.success, out.reason) == (False, "too_wide")


def test_pads_stop_before_the_object_when_commanded_wider(box):
    out = World(box).close_gripper(frontal(), 0.08)
    assert (out.success, out.reason) == (False, "pads_stop_before_contact")
    assert out.width == pytest.approx(0.08)


def test_held_object_follows_the_gripper_and_is_set_down_upright(box):
    w = World(box)
    G = frontal()
    assert w.close_gripper(G, 0.0).success
    T_go = np.linalg.inv(G) @ w.true_object_pose()
    # lift, turn 30 degrees about the vertical through the object centre, tilt a little, lower
    lift = make_transform(translation=[0, 0, 0.08]) @ G
    w.move_gripper(lift)
    assert w.true_object_pose()[2, 3] == pytest.approx(0.08, abs=1e-9)
    turn = make_transform(rotation_about_axis([0, 0, 1], np.radians(30.0)))
    c = np.array([OBJ_XY[0], OBJ_XY[1], 0.0])
    turned = make_transform(translation=c) @ turn @ make_transform(translation=-c) @ lift
    tilted = turned @ make_transform(rotation_about_axis([1, 0, 0], np.radians(6.0)))
    w.move_gripper(tilted)
    np.testing.assert_allclose(w.true_object_pose(), tilted @ T_go, atol=1e-12)
    info = w.open_gripper()
    T = w.true_object_pose()
    assert not w.attached and w.gripper_opening == pytest.approx(w.gripper.max_opening)
    np.testing.assert_allclose(T[:3, 2], [0, 0, 1], atol=1e-12)  # upright
    assert T[2, 3] == 0.0  # bottom on the table
    assert np.degrees(yaw_of(T)) == pytest.approx(30.0, abs=1e-6)  # ideal: exactly the gripper's turn
    assert info["achieved_turn_deg"] == pytest.approx(30.0, abs=1e-6)
    np.testing.assert_allclose(T[:2, 3], (tilted @ T_go)[:2, 3], atol=1e-12)  # where it was released


def test_forced_slip_then_a_regrasp_succeeds(box):
    w = World(box, profile="robot-turned", seed=0)
    w.force_next_grasp_slip()
    out = w.close_gripper(frontal(), 0.0)
    assert (out.success, out.reason) == (False, "slip")
    assert not w.attached and w.true_object_pose()[2, 3] == 0.0
    assert np.linalg.norm(w.true_object_pose()[:2, 3] - OBJ_XY) < 0.01
    w.set_gripper_opening(0.1)
    w.profile = dataclasses.replace(w.profile, slip_prob=0.0)
    assert w.close_gripper(frontal(y=float(w.true_object_pose()[1, 3])), 0.0).success


def test_cannot_turn_by_hand_while_held(box):
    w = World(box)
    assert w.close_gripper(frontal(), 0.0).success
    with pytest.raises(SimStateError):
        w.turn_object(30.0)
    out = w.close_gripper(frontal(), 0.0)
    assert out.reason == "already_holding"


def test_render_frame_truth_and_belief(box):
    ideal = World(box, profile="ideal")
    T_cam = make_transform(np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]]), [0.0, 0.0, 0.1])
    f = ideal.render_frame(T_cam, SMALL, 1)
    np.testing.assert_array_equal(f.T_base_camera, f.T_base_camera_true)
    assert f.meta["object"] == "carton" and f.intrinsics.width == 320
    np.testing.assert_array_equal(f.meta["T_base_object_true"], ideal.true_object_pose())

    w = World(box, profile="hand-turned", seed=5)
    frames = [w.render_frame(T_cam, SMALL, k) for k in range(4)]
    errs = [transform_error(fr.T_base_camera, fr.T_base_camera_true) for fr in frames]
    p = w.profile
    for t_err, r_err in errs:  # hand-eye (2 mm, 0.3 deg) plus per-frame joint jitter
        assert 0.5 * p.hand_eye_mm * 1e-3 < t_err < 2.5 * p.hand_eye_mm * 1e-3
        assert 0.5 * p.hand_eye_deg < r_err < 2.0 * p.hand_eye_deg
    # the hand-eye part is the same in every frame: frames disagree only by the jitter
    jitter = [rotation_angle_deg(np.linalg.inv(frames[0].T_base_camera) @ fr.T_base_camera) for fr in frames[1:]]
    assert max(jitter) < 0.5
    assert max(jitter) > 0.0


def test_same_seed_and_seq_render_the_same_frame(box):
    T_cam = make_transform(np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]]), [0.0, 0.0, 0.1])
    a = World(box, profile="hand-turned", seed=9).render_frame(T_cam, SMALL, 3)
    w = World(box, profile="hand-turned", seed=9)
    w.render_frame(T_cam, SMALL, 1)  # other captures in between do not change frame 3
    b = w.render_frame(T_cam, SMALL, 3)
    c = w.render_frame(T_cam, SMALL, 4)
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.color, b.color)
    np.testing.assert_array_equal(a.T_base_camera, b.T_base_camera)
    assert not np.array_equal(a.depth, c.depth)


def test_render_frame_uses_the_reported_camera_pose(box):
    w = World(box)
    with pytest.raises(SimStateError):
        w.render_frame(None, SMALL)
    T_cam = make_transform(np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]]), [0.0, 0.0, 0.1])
    w.set_joint_state([f"j{i}" for i in range(6)], np.zeros(6), T_base_camera=T_cam)
    np.testing.assert_array_equal(w.render_frame(None, SMALL).T_base_camera_true, T_cam)


def test_joint_state_moves_a_held_object(box):
    w = World(box)
    assert w.close_gripper(frontal(), 0.0).success
    G2 = frontal(z=0.2)
    w.set_joint_state(["a"], [0.0], T_base_gripper=G2)
    assert w.true_object_pose()[2, 3] == pytest.approx(0.2 - 0.075, abs=1e-9)


def test_state_is_json_and_reset_restores(box):
    w = World(box, profile="robot-turned", seed=2, object_pose=default_object_pose(0.4, 0.05, 10.0))
    w.turn_object(30.0)
    w.render_frame(make_transform(translation=[0, 0, 0.3]), SMALL, 0)
    s = json.loads(json.dumps(w.state()))
    assert s["profile"] == "robot-turned" and s["seed"] == 2 and s["counts"]["turns"] == 1
    assert "T_base_object" in s["ground_truth"] and "hand_eye_error" in s["ground_truth"]
    first_turn = s["ground_truth"]["last_set_down"]["achieved_turn_deg"]
    w.reset()
    np.testing.assert_allclose(w.true_object_pose(), default_object_pose(0.4, 0.05, 10.0))
    assert w.counts["turns"] == 0
    assert w.turn_object(30.0) == pytest.approx(first_turn)  # same seed, same draws
    w.reset(3)
    assert w.seed == 3


def test_bad_inputs_are_typed_errors(box):
    w = World(box)
    with pytest.raises(SimInputError):
        w.close_gripper(np.full((4, 4), np.nan))
    with pytest.raises(SimInputError):
        w.move_gripper(np.eye(3))
    with pytest.raises(SimInputError):
        w.set_gripper_opening(-1.0)
    with pytest.raises(SimInputError):
        w.turn_object(float("nan"))
    with pytest.raises(SimInputError):
        w.set_joint_state(["a", "b"], [0.0])
    with pytest.raises(SimInputError):
        World(box, profile="no-such-profile")


def test_hope_milk_frontal_grasp(tmp_path):
    from tests.conftest import shared_data

    shared_data("hope", "milk")
    w = World("milk")
    out = w.close_gripper(frontal(z=0.09), 0.0)
    assert out.success and out.width == pytest.approx(0.073, abs=0.003)


def test_world_loads_a_user_mesh_with_scale_and_up_axis(tmp_path):
    path = write_box_ply(tmp_path, (6.0, 15.0, 6.0), name="cm_y_up")  # centimetres, y up
    w = World(str(path), scale=0.01, up_axis="y")
    np.testing.assert_allclose(w.obj.extent, [0.06, 0.06, 0.15], atol=1e-9)
    assert w.close_gripper(frontal(), 0.0).success


def test_concurrent_renders_equal_sequential_ones(box):
    """The service renders from worker threads: frames must not depend on interleaving."""
    import concurrent.futures as cf

    w = World(box, profile="hand-turned", seed=1)
    T_cam = make_transform(np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]]), [0.2, 0.0, 0.1])
    with cf.ThreadPoolExecutor(3) as ex:
        got = list(ex.map(lambda i: w.render_frame(T_cam, SMALL, i), range(6)))
    for i, f in enumerate(got):
        ref = World(box, profile="hand-turned", seed=1).render_frame(T_cam, SMALL, i)
        np.testing.assert_array_equal(f.depth, ref.depth)
        np.testing.assert_array_equal(f.color, ref.color)
