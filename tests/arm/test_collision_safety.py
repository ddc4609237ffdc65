"""Collision refusals with the pair named, the safety envelope, and "refused means nothing moved"."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from services.arm.arm import ArmConfig, ArmController
from services.arm.collision import CollisionWorld
from services.arm.drivers.sim import SimArmDriver
from services.arm.errors import BadCommand, CollisionError, EnvelopeError
from services.arm.motion import MotionLimits, plan_joint_motion
from services.arm.safety import SafetyEnvelope
from tests.arm.conftest import Q_HOME

# a top-down grasp of an object standing at (0.36, 0, 0) (the conventions' object position)
T_TOPDOWN = np.eye(4)
T_TOPDOWN[:3, :3] = Rotation.from_euler("y", 90, degrees=True).as_matrix()
T_TOPDOWN[:3, 3] = [0.36, 0.0, 0.12]


@pytest.fixture(scope="module")
def world(kin):
    return CollisionWorld(kin)


def test_home_is_free_and_the_table_is_where_the_conventions_say(world, kin):
    assert world.first_contact(Q_HOME, opening=0.1) is None
    # shoulder pitched down: the forearm goes through the table top
    assert kin.fk(np.array([0, 1.6, 0, 0, 0, 0]), "flange")[2, 3] < 0
    c = world.first_contact(np.array([0, 1.6, 0, 0, 0, 0]), opening=0.1)
    assert c is not None and c.body_b == "table" and c.body_a.startswith("robot1/")


def test_motion_through_the_table_is_refused_with_the_pair_named(world):
    traj = plan_joint_motion(np.array([0, 0.3, -0.8, 0, 0.5, 0]), np.array([0, 1.7, -0.3, 0, 0.5, 0]))
    with pytest.raises(CollisionError) as e:
        world.check_trajectory(traj)
    assert e.value.detail["link_b"] == "table"
    assert e.value.detail["link_a"].startswith("robot1/")
    assert 0 < e.value.detail["t_approx"] < traj.duration


def test_collision_free_motion_passes(world):
    traj = plan_joint_motion(np.array([0, 0.3, -0.8, 0, 0.5, 0]), np.array([1.0, 0.1, -0.6, 0, 0.5, 0]))
    assert world.check_trajectory(traj) > 10


def test_object_box_blocks_the_hand_unless_contact_is_allowed(kin):
    world = CollisionWorld(kin)
    q = kin.ik(T_TOPDOWN, Q_HOME).q
    assert world.first_contact(q, 0.08) is None
    world.set_object_footprint([0.36, 0.0], height=0.2, radius=0.04)
    c = world.first_contact(q, 0.08)
    assert c is not None and "object" in (c.body_a, c.body_b)
    assert world.first_contact(q, 0.08, allow_hand_object=True) is None  # grasping: fingers around it
    world.clear_object()
    assert world.first_contact(q, 0.08) is None


def test_self_collision_is_detected_between_non_neighbours(kin, world):
    rng = np.random.default_rng(5)
    found = None
    for _ in range(3000):
        q = rng.uniform(kin.lower, kin.upper)
        c = world.first_contact(q, 0.05)
        if c is not None and "table" not in (c.body_a, c.body_b):
            found = c
            break
    assert found is not None
    names = [f"robot1/link{i}" for i in range(1, 7)]
    ia = names.index(found.body_a) if found.body_a in names else 6
    ib = names.index(found.body_b) if found.body_b in names else 6
    assert abs(ia - ib) >= 2  # neighbours touch by construction and are ignored


def test_bad_object_boxes_are_refused(world):
    with pytest.raises(BadCommand):
        world.set_object_box([0, 0], [0.1, 0.1, 0.1])
    with pytest.raises(BadCommand):
        world.set_object_box([0.3, 0, 0.1], [0.1, -0.1, 0.1])


# ---------------------------------------------------------------- envelope
@pytest.fixture(scope="module")
def env(kin):
    return SafetyEnvelope(kin)


def test_joint_limits_are_enforced_with_the_joint_named(env, kin):
    q = Q_HOME.copy()
    q[4] = kin.upper[4] + 0.05
    with pytest.raises(EnvelopeError) as e:
        env.check_joints(q)
    assert e.value.code == "joint_limit" and e.value.detail["joint"] == "robot1/joint5"
    with pytest.raises(BadCommand):
        env.check_joints([0, 0, 0])


def test_tcp_height_and_workspace_box(env):
    T = np.eye(4)
    T[:3, 3] = [0.4, 0.0, 0.005]
    with pytest.raises(EnvelopeError) as e:
        env.check_tcp(T)
    assert e.value.code == "tcp_height"
    T[:3, 3] = [0.4, 0.9, 0.3]
    with pytest.raises(EnvelopeError) as e:
        env.check_tcp(T)
    assert e.value.code == "workspace"
    T[:3, 3] = [0.4, 0.0, 0.3]
    env.check_tcp(T)


def test_trajectory_faster_than_the_caps_is_refused(env):
    fast = MotionLimits(max_velocity=3.0, max_acceleration=10.0, max_jerk=100.0)
    traj = plan_joint_motion(Q_HOME, Q_HOME + np.array([1.0, 0.2, 0.2, 0.5, 0.2, 1.5]), fast)
    with pytest.raises(EnvelopeError) as e:
        env.check_trajectory(traj)
    assert e.value.code in {"velocity_limit", "acceleration_limit"}
    with pytest.raises(EnvelopeError):
        env.check_limits_fit(fast)


def test_gripper_force_and_opening(env):
    assert env.check_gripper(0.05, 30.0) == (0.05, 30.0)
    with pytest.raises(EnvelopeError) as e:
        env.check_gripper(0.05, 500.0)
    assert e.value.code == "gripper_force"
    with pytest.raises(EnvelopeError) as e:
        env.check_gripper(0.2, 10.0)
    assert e.value.code == "gripper_opening"
    with pytest.raises(BadCommand):
        env.check_gripper(float("nan"), 10.0)


def test_streamed_setpoint_jump_is_refused(env):
    with pytest.raises(EnvelopeError) as e:
        env.check_setpoint(Q_HOME + 0.3, Q_HOME, 0.01)
    assert e.value.code == "velocity_limit"


# ---------------------------------------------------------------- refused means nothing moved
@pytest.fixture
def sim_arm(kin):
    sent: list = []
    ctl = ArmController(SimArmDriver(send=lambda q, o: sent.append(q)), ArmConfig(realtime=False), kinematics=kin)
    ctl.connect()
    return ctl, sent


def test_refused_commands_never_move_the_arm(sim_arm):
    ctl, sent = sim_arm
    with pytest.raises((CollisionError, EnvelopeError)):  # the TCP would also go under the table
        ctl.move_joints([0, 1.7, -0.3, 0, 0.5, 0])
    # an obstacle box in the path of the TCP: refused by the collision check, the pair named
    goal = Q_HOME + np.array([1.0, 0, 0, 0, 0, 0])
    mid = ctl.kinematics.fk(Q_HOME + np.array([0.5, 0, 0, 0, 0, 0]))[:3, 3]
    ctl.collision.set_object_box(mid, [0.06, 0.06, 0.06])
    with pytest.raises(CollisionError) as e:
        ctl.move_joints(goal)
    assert e.value.detail["link_b"] == "object"
    ctl.collision.clear_object()
    bad = Q_HOME.copy()
    bad[1] = 2.5
    with pytest.raises(EnvelopeError):
        ctl.move_joints(bad)
    low = ctl.state()["T_base_gripper"]
    low[2, 3] = 0.0
    with pytest.raises(EnvelopeError):
        ctl.move_linear(low)
    with pytest.raises(BadCommand):
        ctl.move_pose(np.full((4, 4), np.nan))
    with pytest.raises(EnvelopeError):
        ctl.gripper(0.05, 1000.0)
    assert sent == []
    np.testing.assert_allclose(ctl.state()["q"], Q_HOME)
