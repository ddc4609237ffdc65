"""ArmController over the sim and replay drivers: moves end where asked, e-stop halts, state is consistent."""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest

from common.geometry import transform_error
from services.arm.arm import ArmConfig, ArmController
from services.arm.drivers.base import execute
from services.arm.drivers.replay import ReplayArmDriver
from services.arm.drivers.sim import SimArmDriver
from services.arm.errors import ArmError, BadCommand, MotionStopped, ReadOnlyDriver
from services.arm.motion import plan_joint_motion
from tests.arm.conftest import Q_HOME


class Recorder:
    """The sim transport stand-in: keeps every (time, q, opening) sent."""

    def __init__(self):
        self.sent: list[tuple[float, np.ndarray, float]] = []

    def __call__(self, q, opening):
        self.sent.append((time.perf_counter(), q, opening))


@pytest.fixture
def arm(kin):
    rec = Recorder()
    ctl = ArmController(SimArmDriver(send=rec), ArmConfig(realtime=False), kinematics=kin)
    ctl.connect()
    return ctl, rec


def test_move_joints_streams_to_the_goal(arm):
    ctl, rec = arm
    goal = np.array([0.3, 0.0, -1.0, 0.0, 1.0, 0.2])
    info = ctl.move_joints(goal)
    assert info["setpoints_sent"] == len(rec.sent) >= info["duration_s"] * ctl.config.rate_hz
    np.testing.assert_allclose(rec.sent[-1][1], goal, atol=1e-9)
    np.testing.assert_allclose(ctl.state()["q"], goal, atol=1e-9)


def test_move_pose_and_linear_reach_their_targets(arm, kin):
    ctl, rec = arm
    T = kin.fk(np.array([0.2, 0.1, -1.1, 0.1, 1.1, 0.0]))
    ctl.move_pose(T)
    dt, dr = transform_error(ctl.state()["T_base_gripper"], T)
    assert dt < 1e-4 and dr < 0.1
    T2 = T.copy()
    T2[2, 3] -= 0.08  # set down
    ctl.move_linear(T2, speed_scale=0.5)
    dt, dr = transform_error(kin.fk(rec.sent[-1][1]), T2)
    assert dt < 1e-4 and dr < 0.1


def test_dry_run_checks_without_moving(arm, kin):
    ctl, rec = arm
    info = ctl.move_pose(kin.fk(np.array([0.4, 0.1, -1.1, 0.1, 1.1, 0.0])), dry_run=True)
    assert info["duration_s"] > 0 and info["collision_samples"] > 0
    assert rec.sent == []


def test_state_reports_consistent_poses(arm, kin):
    ctl, _ = arm
    s = ctl.state()
    assert set(s) >= {"q", "T_base_gripper", "T_base_camera", "gripper_opening", "moving", "names"}
    np.testing.assert_allclose(s["T_base_gripper"], kin.fk(s["q"]), atol=1e-12)
    np.testing.assert_allclose(s["T_base_camera"], s["T_base_gripper"] @ kin.T_gripper_camera, atol=1e-12)
    t0 = time.perf_counter()
    for _ in range(200):
        ctl.state()
    assert (time.perf_counter() - t0) / 200 < 0.005  # far below the 20 ms of a 50 Hz stream


def test_estop_halts_a_running_motion_and_latches(kin):
    rec = Recorder()
    ctl = ArmController(SimArmDriver(send=rec), ArmConfig(realtime=True), kinematics=kin)
    ctl.connect()
    goal = np.array([-0.8, 0.1, -1.2, 0.3, 1.1, 0.5])
    errors: list[BaseException] = []

    def run():
        try:
            ctl.move_joints(goal)
        except BaseException as e:  # noqa: BLE001 - handed to the test thread
            errors.append(e)

    th = threading.Thread(target=run)
    th.start()
    while not ctl.state()["moving"]:
        time.sleep(0.005)
    time.sleep(0.25)
    t_stop = time.perf_counter()
    ctl.estop()
    th.join(timeout=2.0)
    assert not th.is_alive()
    assert len(errors) == 1 and isinstance(errors[0], MotionStopped)
    # nothing was sent after the stop (one set-point may have been in flight), and the goal was not reached
    assert sum(t > t_stop + 0.002 for t, _, _ in rec.sent) <= 1
    assert np.max(np.abs(rec.sent[-1][1] - goal)) > 0.1
    assert not ctl.state()["moving"]
    with pytest.raises(MotionStopped) as e:
        ctl.move_joints(Q_HOME)
    assert e.value.code == "estop_latched"
    ctl.reset_estop()
    ctl.config.realtime = False
    ctl.move_joints(Q_HOME)
    np.testing.assert_allclose(rec.sent[-1][1], Q_HOME, atol=1e-9)


def test_second_motion_while_moving_is_refused(kin):
    ctl = ArmController(SimArmDriver(send=Recorder()), ArmConfig(realtime=True), kinematics=kin)
    ctl.connect()

    def run():
        with pytest.raises(MotionStopped):
            ctl.move_joints(np.array([0.5, 0.0, -1.0, 0.0, 1.0, 0.0]))

    th = threading.Thread(target=run)
    th.start()
    while not ctl.state()["moving"]:
        time.sleep(0.005)
    with pytest.raises(ArmError) as e:
        ctl.move_joints(Q_HOME)
    assert e.value.code == "busy"
    ctl.estop()
    th.join(timeout=2.0)


def test_execute_faster_than_real_time_and_in_real_time():
    drv = SimArmDriver(send=Recorder())
    drv.connect()
    traj = plan_joint_motion(Q_HOME, Q_HOME + 0.2)
    r = execute(drv, traj, rate_hz=100.0, realtime=False)
    assert r.completed and r.elapsed_s < traj.duration / 5
    r = execute(drv, traj, rate_hz=100.0, realtime=True)
    assert r.completed and r.elapsed_s == pytest.approx(traj.duration, abs=0.05)


def test_gripper_command_reaches_the_opening(arm):
    ctl, rec = arm
    out = ctl.gripper(0.04, 20.0)
    assert out["opening"] == pytest.approx(0.04) and not out["grasped"]
    assert rec.sent[-1][2] == pytest.approx(0.04)


def test_replay_reports_recorded_joints_and_refuses_motion(tmp_path):
    from common.messages import Intrinsics, RGBDFrame
    from common.session_folder import write_scan, write_session

    intr = Intrinsics(width=4, height=4, fx=5.0, fy=5.0, cx=2.0, cy=2.0)
    frame = RGBDFrame(
        color=np.zeros((4, 4, 3), np.uint8), depth=np.zeros((4, 4), np.uint16), intrinsics=intr, T_base_camera=np.eye(4)
    )
    recorded = [Q_HOME, Q_HOME + 0.1, Q_HOME - 0.1]
    write_session(tmp_path, {"views": [{"index": 0, "commanded_turn_deg": 0.0}]})
    for k, q in enumerate(recorded):
        extra = {"joints": {"position": q.tolist(), "gripper_opening": 0.1}} if k != 1 else {"joints": q.tolist()}
        write_scan(tmp_path, 0, k, frame, extra=extra)
    drv = ReplayArmDriver.from_session(tmp_path)
    assert drv.labels == ["view_00/scan_0", "view_00/scan_1", "view_00/scan_2"]
    seen = [drv.read_joints()]
    while drv.advance():
        seen.append(drv.read_joints())
    np.testing.assert_allclose(np.array(seen), np.array(recorded))
    assert json.loads((tmp_path / "view_00" / "scan_2" / "meta.json").read_text())["joints"]["gripper_opening"] == 0.1
    with pytest.raises(ReadOnlyDriver):
        drv.write_setpoint(Q_HOME)
    with pytest.raises(ReadOnlyDriver):
        drv.set_gripper(0.05, 10.0)


def test_dry_run_from_a_given_start_plans_a_chain_without_moving(arm, kin):
    """A chain of moves is checked before the first one runs: each dry run starts where the last would end."""
    ctl, rec = arm
    q_before = ctl.state()["q"].copy()
    T0 = kin.fk(Q_HOME)
    T1 = T0.copy()
    T1[:3, 3] += [0.05, 0.0, -0.05]
    first = ctl.move_pose(T0, dry_run=True)
    second = ctl.move_linear(T1, dry_run=True, q_start=first["q_end"])
    np.testing.assert_allclose(kin.fk(second["q_end"]), T1, atol=1e-5)
    np.testing.assert_allclose(second["frames_end"]["gripper"], T1, atol=1e-5)
    np.testing.assert_allclose(ctl.state()["q"], q_before)
    assert rec.sent == []
    with pytest.raises(BadCommand) as e:  # a start other than where the arm is makes sense only for a dry run
        ctl.move_linear(T1, q_start=first["q_end"])
    assert e.value.code == "bad_value"
