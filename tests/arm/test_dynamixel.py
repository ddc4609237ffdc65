"""The DYNAMIXEL driver against an emulated Protocol 2.0 bus on a pty: packets, read-back, faults.

These run an X-series arm (XM430, IDs 1-6, gripper ID 7): the driver keeps supporting X servos beside the
DYNAMIXEL-P ones PAPRAS is built from (tests/arm/test_dynamixel_p.py)."""

from __future__ import annotations

import os
import struct
import threading
import time

import numpy as np
import pytest
from dynamixel_sdk import PacketHandler

from services.arm.drivers.base import execute
from services.arm.drivers.dynamixel import DynamixelArmDriver, DynamixelConfig, GripperServoConfig, JointServoConfig
from services.arm.drivers.dynamixel import protocol as p
from services.arm.drivers.dynamixel.control_table import RH_P12_RN_A, X_SERIES
from services.arm.drivers.dynamixel.emulator import DynamixelBusEmulator, rh_p12_rn_gripper, xm_arm_servos
from services.arm.errors import DriverError
from services.arm.motion import plan_joint_motion

pytestmark = pytest.mark.timeout(120)


@pytest.fixture
def bus():
    with DynamixelBusEmulator([*xm_arm_servos(), rh_p12_rn_gripper(7)]) as emu:
        yield emu


def make_driver(emu, **kw) -> DynamixelArmDriver:
    kw.setdefault("joints", [JointServoConfig(i) for i in range(1, 7)])
    kw.setdefault("gripper", GripperServoConfig(dxl_id=7))
    return DynamixelArmDriver(DynamixelConfig(port=emu.port, baudrate=1_000_000, home=(0.0,) * 6, **kw))


def test_crc_and_stuffing_match_the_sdk():
    ph = PacketHandler(2.0)
    rng = np.random.default_rng(0)
    for n in (1, 7, 64, 300):
        data = bytes(rng.integers(0, 256, n, dtype=np.uint8))
        assert p.crc16(data) == ph.updateCRC(0, list(data), len(data))
    raw = b"\x01\xff\xff\xfd\x02\xff\xff\xfd"
    assert p.stuff(raw) == b"\x01\xff\xff\xfd\xfd\x02\xff\xff\xfd\xfd"
    assert p.unstuff(p.stuff(raw)) == raw
    # the e-manual's example: READ id 1, address 132, 4 bytes -> CRC 0x1D15
    pkt = p.build_packet(1, p.READ, struct.pack("<HH", 132, 4))
    assert pkt.hex() == "fffffd0001070002840004001d15"


def test_connect_pings_configures_and_reads_back(bus):
    drv = make_driver(bus)
    drv.connect()
    pings = {k.dxl_id for k in bus.packets(p.PING)}
    assert pings == {1, 2, 3, 4, 5, 6, 7}
    # profile velocity 1.5 rad/s written to every joint in X-series units (0.229 rev/min)
    pv = [k for k in bus.packets(p.WRITE) if struct.unpack_from("<H", k.params)[0] == X_SERIES.profile_velocity]
    assert sorted(k.dxl_id for k in pv) == [1, 2, 3, 4, 5, 6]
    assert struct.unpack_from("<I", pv[0].params, 2)[0] == int(1.5 * 60 / (2 * np.pi) / 0.229)
    np.testing.assert_allclose(drv.read_joints(), np.zeros(6), atol=1e-12)  # all servos at tick 2048
    drv.close()


def test_setpoints_go_out_as_sync_write_and_come_back_as_sync_read(bus):
    joints = [JointServoConfig(i) for i in range(1, 7)]
    joints[1] = JointServoConfig(2, offset_rad=0.1, direction=-1)  # a mounted-backwards servo with an offset
    drv = make_driver(bus, joints=joints)
    drv.connect()
    drv.torque(True)
    torque_writes = [k for k in bus.packets(p.WRITE) if struct.unpack_from("<H", k.params)[0] in (64, 512)]
    assert {k.dxl_id for k in torque_writes if k.params[2] == 1} == {1, 2, 3, 4, 5, 6, 7}
    bus.clear_log()
    q = np.array([0.1, -0.2, 0.3, -0.05, 0.25, -0.3])
    steps = 30
    for k in range(1, steps + 1):
        drv.write_setpoint(q * k / steps)
        time.sleep(0.01)
    sw = bus.packets(p.SYNC_WRITE)
    assert len(sw) == steps
    addr, length = struct.unpack_from("<HH", sw[-1].params)
    assert (addr, length) == (X_SERIES.goal_position, 4)
    body = sw[-1].params[4:]
    ticks = {body[i]: struct.unpack_from("<i", body, i + 1)[0] for i in range(0, len(body), 5)}
    expected = {j.dxl_id: j.to_ticks(v) for j, v in zip(joints, q, strict=True)}
    assert ticks == expected
    assert ticks[2] == round(2048 - (-0.2 - 0.1) * 4096 / (2 * np.pi))  # direction -1, offset 0.1
    sr = bus.packets(p.SYNC_READ)
    assert len(sr) >= steps and struct.unpack_from("<HH", sr[0].params) == (X_SERIES.present_position, 4)
    assert list(sr[0].params[4:]) == [1, 2, 3, 4, 5, 6]
    time.sleep(0.2)
    np.testing.assert_allclose(drv.read_joints(), q, atol=2 * np.pi / 4096)  # within one tick
    assert bus.crc_errors == 0
    drv.close()


def test_gripper_current_and_position(bus):
    drv = make_driver(bus)
    drv.connect()
    drv.torque(True)
    drv.set_gripper(0.053, 30.0)
    g = bus.servos[7]
    assert struct.unpack_from("<h", g.memory, RH_P12_RN_A.goal_current)[0] == round(30.0 / (170.0 / 1984.0))
    assert struct.unpack_from("<i", g.memory, RH_P12_RN_A.goal_position)[0] == 370  # half of 740 = half open
    deadline = time.time() + 3.0
    while abs(drv.read_gripper() - 0.053) > 0.001 and time.time() < deadline:
        time.sleep(0.05)
    assert drv.read_gripper() == pytest.approx(0.053, abs=0.001)
    drv.close()


def test_silent_servo_is_named(bus):
    drv = make_driver(bus)
    drv.connect()
    drv.torque(True)
    bus.servos[4].silent = True
    with pytest.raises(DriverError) as e:
        drv.write_setpoint(np.zeros(6))
    assert e.value.code == "servo_silent" and e.value.detail["ids"] == [4]
    drv.close()


def test_silent_servo_at_connect(bus):
    bus.servos[7].silent = True
    with pytest.raises(DriverError) as e:
        make_driver(bus).connect()
    assert e.value.code == "servo_silent" and e.value.detail["id"] == 7


def test_servo_alert_stops_a_running_motion(bus):
    drv = make_driver(bus, error_check_every=5)
    drv.connect()
    drv.torque(True)
    traj = plan_joint_motion(np.zeros(6), np.array([0.4, 0.2, -0.3, 0.1, 0.3, 0.5]))
    threading.Timer(0.3, lambda: setattr(bus.servos[3], "alert", 0x20)).start()  # overload error bit
    sent: list = []
    t0 = time.perf_counter()
    with pytest.raises(DriverError) as e:
        execute(drv, traj, rate_hz=50.0, realtime=True, on_setpoint=lambda t, q: sent.append(t))
    assert e.value.code in {"servo_error", "tracking_error"}
    assert time.perf_counter() - t0 < traj.duration  # stopped early
    assert len(sent) < traj.duration * 50
    drv.close()


def test_emulator_answers_raw_packets_and_flags_bad_crc(bus):
    fd = os.open(bus.port, os.O_RDWR | os.O_NOCTTY)
    try:
        os.write(fd, p.build_packet(3, p.READ, struct.pack("<HH", X_SERIES.present_position, 4)))
        reply = _read_packet(fd)
        assert reply.dxl_id == 3 and reply.instruction == p.STATUS and reply.crc_ok
        assert reply.params[0] == 0 and struct.unpack_from("<i", reply.params, 1)[0] == 2048
        bad = bytearray(p.build_packet(3, p.READ, struct.pack("<HH", 132, 4)))
        bad[-1] ^= 0xFF
        os.write(fd, bytes(bad))
        reply = _read_packet(fd)
        assert reply.params[0] == p.ERR_CRC
        assert bus.crc_errors == 1
    finally:
        os.close(fd)


def _read_packet(fd: int, timeout: float = 1.0) -> p.Packet:
    buf = bytearray()
    deadline = time.time() + timeout
    while time.time() < deadline:
        import select

        r, _, _ = select.select([fd], [], [], 0.05)
        if r:
            buf.extend(os.read(fd, 256))
            pkts = p.parse_packets(buf)
            if pkts:
                return pkts[0]
    raise AssertionError("no status packet")
