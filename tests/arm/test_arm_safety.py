"""The real arm is safe to power: it stops at once, holds where it is after a fault, the gripper obeys the e-stop,
and a servo that falls silent is named (the e-stop never claims a hold it could not write).

The arm service runs as a real process over Zenoh with the DYNAMIXEL driver on the emulated PAPRAS bus
(every read and write through dynamixel-sdk as Protocol 2.0 packets). Faults are injected into that bus
through its fault file (``OBJSCAN_EMULATED_BUS_FAULTS``): a joint blocked short of its goal until released,
a servo that stops answering. The gripper's e-stop is checked in this process on the same driver and
emulator, where the emulated servo's own position is the ground truth.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from common import keys
from common.api import MoveRequest, MoveResult
from common.client import request_sync
from common.codec import decode
from common.errors import RemoteError
from common.launcher import ProcessSpec
from common.messages import JointState, Ok, Request
from services.arm.arm import ArmConfig, ArmController
from services.arm.drivers.dynamixel import DynamixelConfig
from services.arm.drivers.dynamixel.driver import DynamixelArmDriver
from services.arm.drivers.dynamixel.emulator import FAULT_FILE_ENV, DynamixelBusEmulator, write_faults
from services.arm.drivers.dynamixel.robot_config import load_robot_config
from services.arm.errors import MotionStopped

ROBOT = keys.DEFAULT_ROBOT
pytestmark = pytest.mark.timeout(300)
BLOCK_RAD = 0.15  # joint 1 stops this far short of its goal, as the obstruction of the report


class Cell:
    """The sim twin and the arm service (dynamixel backend, emulated bus) plus the bus's fault file."""

    def __init__(self, group, fault_file) -> None:  # noqa: ANN001
        self.group = group
        self.session = group.session
        self.fault_file = fault_file
        self.samples: list[tuple[float, JointState]] = []
        self._lock = threading.Lock()
        self._sub = self.session.declare_subscriber(keys.arm(ROBOT, "state"), self._on_state)

    def _on_state(self, sample) -> None:  # noqa: ANN001
        msg = decode(sample.payload.to_bytes())
        if isinstance(msg, JointState):
            with self._lock:
                self.samples.append((time.monotonic(), msg))
                del self.samples[:-2000]

    def since(self, t0: float) -> list[JointState]:
        with self._lock:
            return [m for t, m in self.samples if t >= t0]

    def faults(self, faults: dict) -> None:
        write_faults(self.fault_file, faults)

    def request(self, key: str, msg=None, timeout: float = 60.0):  # noqa: ANN001, ANN201
        return request_sync(self.session, keys.arm(ROBOT, key), msg, timeout=timeout)

    def stop(self) -> tuple[float, object]:
        t0 = time.perf_counter()
        try:
            reply: object = self.request("stop", timeout=30)
        except RemoteError as exc:
            reply = exc
        return time.perf_counter() - t0, reply

    def recover(self) -> None:
        """No faults, the stop reset, the arm at home: the next test starts from a healthy cell."""
        self.faults({})
        time.sleep(0.1)
        self.request("stop", Request(params={"reset": True}), timeout=30)
        self.request("move", MoveRequest(kind="home"), timeout=120)


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    from common.launcher import ServiceGroup

    fault_file = tmp_path_factory.mktemp("bus-faults") / "faults.json"
    write_faults(fault_file, {})
    with ServiceGroup(log_dir=tmp_path_factory.mktemp("arm-safety-logs")) as group:
        group.launch([ProcessSpec("services.sim", service="sim"),
                      ProcessSpec("services.arm", ["--backend", "dynamixel", "--option", "emulate_bus=true"],
                                  service="arm",
                                  env={FAULT_FILE_ENV: str(fault_file)})],
                     timeout=180)
        c = Cell(group, fault_file)
        yield c
        c._sub.undeclare()


def _joint1_target() -> tuple[np.ndarray, np.ndarray]:
    home = np.asarray(load_robot_config().home)
    return home, home + np.array([0.45, 0.0, 0.0, 0.0, 0.0, 0.0])


def _move_in_background(cell: Cell, target: np.ndarray) -> tuple[threading.Thread, list]:
    out: list = []

    def run() -> None:
        try:
            out.append(cell.request("move", MoveRequest(kind="joints", q=target), timeout=120))
        except RemoteError as exc:
            out.append(exc)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t, out


def test_a_stop_during_the_settle_check_of_a_blocked_joint_is_answered_at_once(cell):
    """A stop sent while the settle check waits for a blocked joint is answered at once and ends the move
    (it waited for the whole settle timeout before)."""
    home, target = _joint1_target()
    planned = cell.request("move", MoveRequest(kind="joints", q=target, dry_run=True))
    assert isinstance(planned, MoveResult)
    cell.faults({1: {"block_short_rad": BLOCK_RAD}})
    try:
        t, out = _move_in_background(cell, target)
        time.sleep(planned.duration_s + 0.5)  # the stream has ended; the settle check waits (up to 2 s)
        assert t.is_alive(), out  # still settling
        latency, reply = cell.stop()
        t.join(timeout=30)
        assert isinstance(reply, Ok) and reply.info["estopped"] is True, reply
        assert latency < 0.3, f"stop answered after {latency * 1e3:.0f} ms while settling"
        assert out and isinstance(out[0], RemoteError) and out[0].code == "estop", out  # stopped, not settled
        state = cell.request("state", timeout=10)
        assert state.estop == "held" and not state.moving
    finally:
        cell.recover()


def test_after_a_settle_tracking_error_the_arm_holds_where_it_stopped(cell):
    """Tracking error at settle: the arm holds where it is, the state names the fault, and removing the
    obstruction with no command sent leaves the joint within 0.01 rad of where it stopped for 3 s."""
    home, target = _joint1_target()
    cell.faults({1: {"block_short_rad": BLOCK_RAD}})
    try:
        t, out = _move_in_background(cell, target)
        t.join(timeout=120)
        assert out and isinstance(out[0], RemoteError) and out[0].code == "tracking_error", out
        assert out[0].detail["joint"] == "robot1/joint1"
        time.sleep(0.1)
        state = cell.request("state", timeout=10)
        assert not state.moving
        stopped_at = state.position.copy()
        assert abs(stopped_at[0] - (target[0] - BLOCK_RAD)) < 0.03  # it stopped at the obstruction
        cell.faults({})  # the obstruction is removed; no command is sent
        t0 = time.monotonic()
        time.sleep(3.0)
        seen = cell.since(t0)
        assert len(seen) > 50  # the state stream went on (50 Hz)
        drift = max(float(np.max(np.abs(m.position - stopped_at))) for m in seen)
        assert drift <= 0.01, f"the arm moved {drift:.3f} rad on its own after the fault"
        assert state.fault.get("code") == "tracking_error" and state.fault.get("joint") == "robot1/joint1", state.fault
    finally:
        cell.recover()


def test_a_silent_servo_is_named_and_the_estop_does_not_claim_a_hold_it_could_not_write(cell):
    """Joint 3 stops answering: the state names it; a stop is answered quickly with ``estop_failed`` naming
    the servo (it said ``estopped: True`` before), and the state says the e-stop failed."""
    try:
        t0 = time.monotonic()
        cell.faults({3: {"silent": True}})
        named = named_after = None
        while time.monotonic() - t0 < 3.0 and named is None:
            named = next((m for m in cell.since(t0) if m.fault.get("code") == "servo_silent"), None)
            named_after = time.monotonic() - t0
            time.sleep(0.005)
        latencies = []
        for _ in range(20):
            latency, reply = cell.stop()
            latencies.append(latency)
            assert isinstance(reply, RemoteError) and reply.code == "estop_failed", reply
            assert reply.detail["servos"] == [{"id": 3, "name": "robot1/joint3"}]
            time.sleep(0.02)
        assert float(np.median(latencies)) < 0.1, latencies  # not waiting on the silent servo
        assert named is not None, "the silent servo was never reported"
        assert 3 in named.fault["ids"] and "robot1/joint3" in named.fault["servos"]
        # named at the first read attempt it missed (one packet timeout, ~0.1 s on this bus), not after retries
        assert named_after < 0.45, named_after
        time.sleep(0.1)
        state = cell.request("state", timeout=10)
        assert state.estop == "failed" and state.fault["code"] == "estop_failed"
        health = request_sync(cell.session, keys.health("arm", "*"), timeout=10)
        assert health.info["estopped"] is False and health.info["estop"] == "failed"
        with pytest.raises(RemoteError) as e:  # no motion with a servo that does not answer
            cell.request("move", MoveRequest(kind="home"))
        assert e.value.code == "servo_silent" and e.value.detail["ids"] == [3]
    finally:
        cell.recover()
    state = cell.request("state", timeout=10)  # the servo answers again: reset, healthy
    assert state.estop == "" and not state.fault


def test_estop_halts_the_gripper_while_it_closes(kin, monkeypatch):
    """Closing at 60 N, a stop at about 80 mm: the fingers stop there (they went on closing to 0 mm before)."""
    from dynamixel_sdk import port_handler

    # the emulator shares this process's GIL: the SDK's packet timeout widened as for --emulate-bus (hil.py)
    monkeypatch.setattr(port_handler, "LATENCY_TIMER", max(port_handler.LATENCY_TIMER, 50))
    with DynamixelBusEmulator() as bus:
        ctl = ArmController(DynamixelArmDriver(DynamixelConfig(port=bus.port, retries=4)),  # as hil.py
                            ArmConfig(realtime=True), kinematics=kin)
        ctl.connect()
        g = ctl.driver.config.gripper
        opening = lambda: g.to_opening(bus.snapshot()[g.dxl_id][0])  # noqa: E731 - the servo itself
        assert opening() > 0.1
        out: list = []

        def close() -> None:
            try:
                out.append(ctl.gripper(0.0, 60.0))
            except Exception as exc:  # noqa: BLE001 - checked below
                out.append(exc)

        t = threading.Thread(target=close, daemon=True)
        t.start()
        deadline = time.monotonic() + 5.0
        while opening() > 0.080 and time.monotonic() < deadline:
            time.sleep(0.002)
        ctl.estop()
        at_stop = opening()
        time.sleep(1.0)
        travel = abs(at_stop - opening())
        assert travel < 0.002, f"the fingers went on {travel * 1e3:.1f} mm after the stop"
        t.join(timeout=10)
        assert out and isinstance(out[0], MotionStopped), out
        assert ctl.estopped and ctl.state()["estop"] == "held"
        ctl.close()


def test_the_emulated_bus_takes_its_faults_from_its_fault_file(tmp_path):
    """A blocked joint stops short of any goal until released; a silent servo answers nothing; a fault file
    naming an unknown fault is refused by the writer."""
    faults = tmp_path / "faults.json"
    with DynamixelBusEmulator(fault_file=faults) as bus:
        drv = DynamixelArmDriver(DynamixelConfig(port=bus.port))
        drv.connect()
        q0 = drv.read_joints()
        write_faults(faults, {1: {"block_short_rad": 0.1}, 3: {"silent": True}})
        deadline = time.monotonic() + 5.0
        while not bus.servos[3].silent and time.monotonic() < deadline:
            time.sleep(0.005)
        assert bus.servos[3].silent and bus.servos[1].block_short
        goal = q0 + np.array([0.3, 0, 0, 0, 0, 0])
        j1 = drv.config.joints[0]
        with bus._lock:  # a goal straight into the servo's table, as a sync write would put it
            bus.servos[1].write(bus.servos[1].table.goal_position, j1.to_ticks(goal[0]).to_bytes(4, "little",
                                                                                                signed=True))
        time.sleep(1.0)
        assert j1.to_rad(bus.snapshot()[1][0]) == pytest.approx(goal[0] - 0.1, abs=0.002)  # short of its goal
        write_faults(faults, {})
        time.sleep(1.0)
        assert not bus.servos[3].silent
        assert j1.to_rad(bus.snapshot()[1][0]) == pytest.approx(goal[0], abs=0.002)  # released: it goes on
        drv.close()
    with pytest.raises(ValueError):
        write_faults(faults, {1: {"jammed": True}})
