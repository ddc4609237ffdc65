"""Jerk-limited trajectories: every sampled limit holds, ends are exact, Cartesian lines stay straight."""

from __future__ import annotations

import numpy as np
import pytest

from common.geometry import rotation_about_line
from services.arm.errors import BadCommand, TrajectoryError
from services.arm.motion import (
    LinePathConfig,
    MotionLimits,
    _ruckig_offline,
    cartesian_line_path,
    plan_joint_motion,
    plan_linear_motion,
    plan_path_motion,
)
from tests.arm.conftest import Q_HOME

RATE = 1000.0


def assert_within_limits(traj, lim: MotionLimits, jerk_slack: float = 1e-3):
    s = traj.sample(RATE)
    assert np.all(np.abs(s.qd) <= lim.max_velocity * (1 + 1e-6))
    assert np.all(np.abs(s.qdd) <= lim.max_acceleration * (1 + 1e-6))
    jerk = np.diff(s.qdd, axis=0) / np.diff(s.t)[:, None]
    assert np.all(np.abs(jerk) <= lim.max_jerk * (1 + jerk_slack))
    # numerical derivatives agree with the reported ones (the trajectory is what it says it is)
    qd_num = np.diff(s.q, axis=0) / np.diff(s.t)[:, None]
    qd_mid = 0.5 * (s.qd[1:] + s.qd[:-1])
    np.testing.assert_allclose(qd_num, qd_mid, atol=2e-3)
    return s


def test_joint_trajectory_respects_every_limit_and_ends_at_rest(rng):
    lim = MotionLimits(
        max_velocity=[1.0, 0.8, 1.2, 1.5, 1.5, 2.0], max_acceleration=2.0, max_jerk=[10, 8, 12, 15, 15, 20]
    )
    for _ in range(5):
        q0 = rng.uniform(-1.5, 1.5, 6)
        q1 = rng.uniform(-1.5, 1.5, 6)
        traj = plan_joint_motion(q0, q1, lim)
        s = assert_within_limits(traj, lim)
        np.testing.assert_allclose(s.q[0], q0, atol=1e-12)
        np.testing.assert_allclose(s.q[-1], q1, atol=1e-9)
        np.testing.assert_allclose(s.qd[[0, -1]], 0.0, atol=1e-9)
        # time-optimal and synchronised: exactly as long as the slowest joint alone needs
        alone = [
            _ruckig_offline(
                1, [q0[i]], [q1[i]], [lim.max_velocity[i]], [lim.max_acceleration[i]], [lim.max_jerk[i]]
            ).duration
            for i in range(6)
        ]
        assert traj.duration == pytest.approx(max(alone), rel=1e-9)


def test_speed_scale_slows_the_same_motion_down():
    q0, q1 = np.zeros(6), np.array([1.0, -0.5, 0.3, 0.0, 0.2, 1.0])
    fast = plan_joint_motion(q0, q1)
    slow = plan_joint_motion(q0, q1, speed_scale=0.5)
    assert slow.duration == pytest.approx(2 * fast.duration, rel=1e-6)
    assert_within_limits(slow, MotionLimits().scaled(0.5))


def test_linear_motion_stays_on_the_line_within_limits(kin):
    lim = MotionLimits()
    T0 = kin.fk(Q_HOME)
    T1 = T0.copy()
    T1[:3, 3] += [0.08, 0.05, -0.12]
    traj = plan_linear_motion(kin, Q_HOME, T1, lim)
    s = assert_within_limits(traj, lim, jerk_slack=0.05)
    a, d = T0[:3, 3], T1[:3, 3] - T0[:3, 3]
    for q in s.q[::10]:
        T = kin.fk(q)
        dist = np.linalg.norm(np.cross(T[:3, 3] - a, d)) / np.linalg.norm(d)
        assert dist < 5e-4
        np.testing.assert_allclose(T[:3, :3], T0[:3, :3], atol=2e-3)  # constant orientation along the line
    np.testing.assert_allclose(kin.fk(s.q[-1]), T1, atol=1e-5)


def test_linear_motion_out_of_reach_is_refused(kin):
    T1 = kin.fk(Q_HOME)
    T1[:3, 3] += [0.6, 0.0, 0.0]  # beyond the arm's reach
    with pytest.raises(TrajectoryError) as e:
        plan_linear_motion(kin, Q_HOME, T1)
    assert e.value.code in {"line_unreachable", "line_discontinuous"}
    assert 0.0 < e.value.detail["fraction"] <= 1.0


def test_dense_path_timing_respects_limits():
    u = np.linspace(0, 1, 60)[:, None]
    Q = np.hstack([np.sin(3 * u), u**2, -u, np.cos(2 * u), 0.5 * u, np.zeros_like(u)])
    lim = MotionLimits()
    traj = plan_path_motion(Q, lim)
    s = assert_within_limits(traj, lim, jerk_slack=0.05)
    np.testing.assert_allclose(s.q[-1], Q[-1], atol=1e-9)
    # the binding limit is used: the motion is not needlessly slow
    peak = max(np.max(np.abs(s.qd) / lim.max_velocity), np.sqrt(np.max(np.abs(s.qdd) / lim.max_acceleration)))
    assert peak > 0.9


@pytest.mark.parametrize("scale", [0.0, -1.0, 1.5, np.nan])
def test_bad_speed_scale_is_refused(scale):
    with pytest.raises(BadCommand):
        plan_joint_motion(np.zeros(6), np.ones(6), speed_scale=scale)


def test_bad_joint_vectors_are_refused():
    with pytest.raises(BadCommand):
        plan_joint_motion(np.zeros(6), np.array([0, 0, 0, np.inf, 0, 0]))
    with pytest.raises(BadCommand):
        plan_joint_motion(np.zeros(7), np.zeros(6))
    with pytest.raises(BadCommand):
        MotionLimits(max_velocity=-1.0)


def test_line_near_a_wrist_singularity_is_refined_not_refused(kin):
    """Close to joint 5 = 0 the wrist rolls fast but continuously: halving the step shrinks the joint steps
    (a branch flip would not), so the line is planned with extra points instead of being refused."""
    q = np.array([0.0, 0.5, -1.0, 0.3, 0.1, 0.2])
    T0 = kin.fk(q)
    T1 = rotation_about_line(np.array([0.0, 1.0, 0.0]), T0[:3, 3], np.radians(3.0)) @ T0
    with pytest.raises(TrajectoryError) as e:
        cartesian_line_path(kin, q, T1, config=LinePathConfig(max_refinements=0))
    assert e.value.code == "line_discontinuous"
    cfg = LinePathConfig()
    Q = cartesian_line_path(kin, q, T1, config=cfg)
    assert np.max(np.abs(np.diff(Q, axis=0))) <= cfg.max_joint_step
    np.testing.assert_allclose(kin.fk(Q[-1]), T1, atol=1e-5)
    for qi in Q:  # still on the line: the TCP stays where the rotation keeps it
        assert np.linalg.norm(kin.fk(qi)[:3, 3] - T0[:3, 3]) < 1e-4
