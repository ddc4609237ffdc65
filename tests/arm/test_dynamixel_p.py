"""The DYNAMIXEL driver on the PAPRAS bus (DYNAMIXEL-P servos, RH-P12-RN(A) ID 111), emulated on a pty.

Every servo read and write goes through dynamixel-sdk as real Protocol 2.0 packets; the emulator keeps
P-series control tables (Torque Enable 512, Goal Position 564, Present Position 580, ±501,923 pulses per
half turn on the PH54) and moves a servo only while its torque is on.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from services.arm.arm import ArmConfig, ArmController
from services.arm.drivers.dynamixel import DynamixelConfig, JointServoConfig
from services.arm.drivers.dynamixel import protocol as p
from services.arm.drivers.dynamixel.control_table import PH42_020, PH54_200, RH_P12_RN_A
from services.arm.drivers.dynamixel.driver import DynamixelArmDriver, scan_bus
from services.arm.drivers.dynamixel.emulator import DynamixelBusEmulator, EmulatedServo, servos_for
from services.arm.drivers.replay.driver import ReplayArmDriver
from services.arm.drivers.sim.driver import SimArmDriver
from services.arm.errors import DriverError

pytestmark = pytest.mark.timeout(120)

PAPRAS_IDS = [1, 2, 3, 4, 5, 6, 111]


@pytest.fixture
def bus():
    with DynamixelBusEmulator() as emu:  # the default bus: PAPRAS from the shipped robot configuration
        yield emu


def papras(emu: DynamixelBusEmulator, **kw) -> DynamixelArmDriver:
    return DynamixelArmDriver(DynamixelConfig(port=emu.port, **kw))


def _writes(emu: DynamixelBusEmulator, addr: int) -> list[tuple[int, p.Packet]]:
    return [(k, pk) for k, pk in enumerate(emu.log)
            if pk.instruction == p.WRITE and struct.unpack_from("<H", pk.params)[0] == addr]


def test_p_series_units():
    j = JointServoConfig(1, "PH54-200-S500-R")
    assert j.to_ticks(math.pi) == 501_923 and j.to_ticks(-math.pi) == -501_923 and j.to_ticks(0.0) == 0
    assert JointServoConfig(5, "PH42-020-S300-R").to_ticks(math.pi / 2) == round(303_750 / 2)
    assert PH54_200.torque_enable == 512 and PH54_200.goal_position == 564 and PH54_200.present_position == 580
    # hardware.yaml's Profile Velocity 750 = 7.5 rev/min
    assert PH54_200.rad_per_s(750) == pytest.approx(7.5 * 2 * math.pi / 60)


def test_torque_is_on_before_the_first_setpoint_and_a_move_reaches_its_target(bus, kin):
    ctl = ArmController(papras(bus), ArmConfig(realtime=True), kinematics=kin)
    ctl.connect()
    after_connect = len(bus.log)
    # connect: every servo got its goal = present, then torque on; nothing moved
    torque_on = {pk.dxl_id: k for k, pk in _writes(bus, 512) if pk.params[2] == 1}
    assert sorted(torque_on) == PAPRAS_IDS and max(torque_on.values()) < after_connect
    hold = [k for k, pk in enumerate(bus.log) if pk.instruction == p.SYNC_WRITE
            and struct.unpack_from("<H", pk.params)[0] == 564]
    assert hold and hold[0] < min(torque_on[i] for i in range(1, 7))
    assert all(bus.servos[i].torque_on for i in PAPRAS_IDS)
    home = np.asarray(ctl.driver.config.home)
    np.testing.assert_allclose(ctl.state()["q"], home, atol=1e-5)

    target = home + np.array([0.25, -0.2, 0.15, 0.3, -0.2, 0.3])
    info = ctl.move_joints(target)
    assert info["setpoints_sent"] > 10
    first_setpoint = next(k for k, pk in enumerate(bus.log) if k >= after_connect and pk.instruction == p.SYNC_WRITE)
    assert first_setpoint > max(torque_on.values())
    np.testing.assert_allclose(ctl.driver.read_joints(), target, atol=ctl.driver.config.settle_tolerance)
    # where the emulated motors are, in their own pulses (joint 3 with its homing offset)
    for j, v in zip(ctl.driver.config.joints, target, strict=True):
        present = struct.unpack_from("<i", bus.servos[j.dxl_id].memory, 580)[0]
        assert abs(j.to_rad(present) - v) <= ctl.driver.config.settle_tolerance
    # planned under the servos' own Profile Velocity (750 = 0.785 rad/s), so streaming never lagged
    assert np.all(ctl.config.limits.max_velocity <= PH54_200.rad_per_s(750))
    ctl.close()


def test_model_number_mismatch_is_refused_naming_id_expected_and_found(bus):
    servos = servos_for()
    servos[2] = EmulatedServo(3, PH42_020)  # joint 3 should be a PH54-100
    with DynamixelBusEmulator(servos) as emu:
        with pytest.raises(DriverError) as e:
            papras(emu).connect()
        assert e.value.code == "model_mismatch"
        d = e.value.detail
        assert (d["id"], d["expected"], d["found"]) == (3, "PH54-100-S500-R", "PH42-020-S300-R")
        assert d["found_model_number"] == 2000
        msg = str(e.value)
        assert "3" in msg and "PH54-100-S500-R" in msg and "PH42-020-S300-R" in msg
        assert not _writes(emu, 512)  # refused before any torque was enabled


def test_settle_check_fails_on_a_stalled_servo(bus, kin):
    ctl = ArmController(papras(bus), ArmConfig(realtime=True), kinematics=kin)
    ctl.connect()
    bus.servos[4].stalled = True  # answers, takes goals, never moves
    home = np.asarray(ctl.driver.config.home)
    target = home + np.array([0.0, 0.0, 0.0, 0.2, 0.0, 0.0])  # under the 0.35 rad streaming threshold
    with pytest.raises(DriverError) as e:
        ctl.move_joints(target)
    assert e.value.code == "tracking_error"
    assert e.value.detail["joint"] == "robot1/joint4" and e.value.detail["id"] == 4
    assert e.value.detail["error_rad"] == pytest.approx(0.2, abs=0.01)
    assert "robot1/joint4" in str(e.value)
    ctl.close()


def test_a_servo_in_hardware_error_is_refused_at_connect(bus):
    bus.servos[2].alert = 0x20  # overload
    with pytest.raises(DriverError) as e:
        papras(bus).connect()
    assert e.value.code == "servo_error" and e.value.detail["faults"] == {2: ["overload"]}


def test_home_works_on_every_backend(bus, kin):
    # dynamixel: move away, then home goes back to the configured home posture
    ctl = ArmController(papras(bus), ArmConfig(realtime=True), kinematics=kin)
    ctl.connect()
    home = np.asarray(ctl.driver.config.home)
    ctl.move_joints(home + np.array([0.2, 0.1, -0.1, 0.0, 0.1, -0.2]))
    ctl.home()
    np.testing.assert_allclose(ctl.driver.read_joints(), home, atol=ctl.driver.config.settle_tolerance)
    ctl.close()
    # sim
    sent: list = []
    sim = ArmController(SimArmDriver(send=lambda q, o: sent.append(q)), ArmConfig(realtime=False), kinematics=kin)
    sim.connect()
    sim.move_joints(np.array([0.3, -0.2, -0.8, 0.1, 1.0, 0.2]))
    sim.home()
    np.testing.assert_allclose(sent[-1], sim.driver.home_q, atol=1e-9)
    # replay: back to the first recorded state
    states = np.array([[0.1] * 6, [0.2] * 6, [0.3] * 6])
    rep = ArmController(ReplayArmDriver(states), ArmConfig(realtime=False), kinematics=kin)
    rep.connect()
    rep.driver.seek(2)
    info = rep.home()
    np.testing.assert_allclose(info["q_end"], states[0])
    np.testing.assert_allclose(rep.state()["q"], states[0])


def test_shutdown_policy(bus):
    drv = papras(bus)  # hold (the default): the arm would fall if the servos went limp
    drv.connect()
    drv.close()
    assert all(bus.servos[i].torque_on for i in PAPRAS_IDS)
    drv = papras(bus, shutdown="relax")
    drv.connect()
    drv.close()
    assert not any(bus.servos[i].torque_on for i in PAPRAS_IDS)


def test_estop_holds_with_torque_on(bus):
    drv = papras(bus)
    drv.connect()
    drv.stop()
    assert all(bus.servos[i].torque_on for i in PAPRAS_IDS)
    for j in drv.config.joints:
        s = bus.servos[j.dxl_id]
        assert s.goal_position == struct.unpack_from("<i", s.memory, 580)[0]
    drv.close()


def test_connect_writes_the_configured_eeprom_and_profiles(bus):
    bus.servos[3].memory[20:24] = struct.pack("<i", 0)  # a fresh servo: no homing offset yet
    drv = papras(bus)
    drv.connect()
    s3 = bus.servos[3]
    assert struct.unpack_from("<i", s3.memory, 20)[0] == -125480  # hardware.yaml's Homing_Offset
    for i in range(1, 7):
        m = bus.servos[i].memory
        assert struct.unpack_from("<I", m, 560)[0] == 750 and struct.unpack_from("<I", m, 556)[0] == 1500
        assert m[9] == 25  # Return_Delay_Time
    g = bus.servos[111].memory
    assert struct.unpack_from("<I", g, 560)[0] == 2900 and struct.unpack_from("<I", g, 556)[0] == 6000
    assert drv.servo_info[111]["model"] == RH_P12_RN_A.name and drv.servo_info[1]["model"] == PH54_200.name
    drv.close()


def test_scan_bus_lists_every_servo(bus):
    found = scan_bus(bus.port)
    assert [f["id"] for f in found] == PAPRAS_IDS
    assert [f["model"] for f in found] == ["PH54-200-S500-R"] * 2 + ["PH54-100-S500-R"] * 2 + [
        "PH42-020-S300-R"] * 2 + ["RH-P12-RN(A)"]
    assert found[-1]["firmware"] == 12
