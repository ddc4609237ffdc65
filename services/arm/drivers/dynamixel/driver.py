"""DYNAMIXEL driver (dynamixel-sdk, Protocol 2.0): sync write of goal positions, sync read of present ones.

Every set-point is a GroupSyncWrite of Goal Position followed by a GroupSyncRead of Present Position, so
a servo that stops answering is noticed within one cycle; every ``error_check_every`` cycles Hardware
Error Status is read too. Either, or a tracking error beyond ``max_tracking_error``, raises
``DriverError`` (the controller then stops the motion). Gripper commands use single writes with status
replies, whose error byte is checked.
"""

from __future__ import annotations

import math
import threading

import numpy as np
from dynamixel_sdk import (
    COMM_SUCCESS,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)

from services.arm.drivers.base import ArmDriver
from services.arm.drivers.dynamixel.config import DynamixelConfig
from services.arm.errors import DriverError

ALERT_BIT = 0x80


def _u32_bytes(v: int) -> list[int]:
    return list(int(v & 0xFFFFFFFF).to_bytes(4, "little"))


def _signed32(v: int) -> int:
    return v - (1 << 32) if v > 0x7FFFFFFF else v


class DynamixelArmDriver(ArmDriver):
    name = "dynamixel"

    def __init__(self, config: DynamixelConfig | None = None):
        self.config = config or DynamixelConfig()
        if len(self.config.joints) != 6:
            raise ValueError("the PAPRAS arm needs 6 joint servos")
        self._ids = [j.dxl_id for j in self.config.joints]
        self._port: PortHandler | None = None
        self._ph = PacketHandler(2.0)
        self._lock = threading.RLock()
        self._cycle = 0
        self._last_goal: np.ndarray | None = None

    # ------------------------------------------------------------------ link
    def _check(self, result: int, error: int, what: str, dxl_id: int) -> None:
        if result != COMM_SUCCESS:
            raise DriverError(
                f"servo {dxl_id} did not answer {what}: {self._ph.getTxRxResult(result)}",
                code="servo_silent",
                detail={"id": dxl_id, "what": what},
            )
        if error:
            raise DriverError(
                f"servo {dxl_id} reported an error on {what}: {self._ph.getRxPacketError(error)}",
                code="servo_error",
                detail={"id": dxl_id, "what": what, "error": int(error)},
            )

    def _retry(self, fn, *args):
        for attempt in range(self.config.retries + 1):
            out = fn(*args)
            if out[-2] == COMM_SUCCESS or attempt == self.config.retries:
                return out
        return out

    def connect(self) -> None:
        with self._lock:
            if self._port is not None:
                return
            cfg = self.config
            port = PortHandler(cfg.port)
            try:
                ok = port.openPort() and port.setBaudRate(cfg.baudrate)
            except Exception as exc:  # pyserial raises SerialException/OSError
                raise DriverError(f"cannot open {cfg.port}: {exc}", code="port_unavailable") from exc
            if not ok:
                raise DriverError(f"cannot open {cfg.port} at {cfg.baudrate} baud", code="port_unavailable")
            self._port = port
            try:
                all_ids = [*self._ids] + ([cfg.gripper.dxl_id] if cfg.gripper else [])
                for dxl_id in all_ids:
                    _, res, err = self._retry(self._ph.ping, port, dxl_id)
                    self._check(res, err & ~ALERT_BIT, "ping", dxl_id)
                t = cfg.joint_table
                self._gsw = GroupSyncWrite(port, self._ph, t.goal_position, 4)
                self._gsr = GroupSyncRead(port, self._ph, t.present_position, 4)
                self._gsr_err = GroupSyncRead(port, self._ph, t.hardware_error, 1)
                for dxl_id in self._ids:
                    self._gsr.addParam(dxl_id)
                    self._gsr_err.addParam(dxl_id)
                self._configure_servos()
            except Exception:
                port.closePort()
                self._port = None
                raise

    def _write(self, dxl_id: int, addr: int, size: int, value: int, what: str) -> None:
        fn = {1: self._ph.write1ByteTxRx, 2: self._ph.write2ByteTxRx, 4: self._ph.write4ByteTxRx}[size]
        res, err = fn(self._port, dxl_id, addr, value & ((1 << (8 * size)) - 1))
        self._check(res, err, what, dxl_id)

    def _configure_servos(self) -> None:
        """Operating mode (EEPROM, torque must be off) and the hardware speed/acceleration caps."""
        cfg, t = self.config, self.config.joint_table
        rpm = cfg.profile_velocity * 60.0 / (2 * math.pi)
        rpm2 = cfg.profile_acceleration * 3600.0 / (2 * math.pi)
        for dxl_id in self._ids:
            if cfg.set_operating_mode:
                torque, res, err = self._ph.read1ByteTxRx(self._port, dxl_id, t.torque_enable)
                self._check(res, err, "read torque", dxl_id)
                if not torque:
                    self._write(dxl_id, t.operating_mode, 1, t.position_mode, "operating mode")
            self._write(dxl_id, t.profile_velocity, 4, max(int(rpm / t.velocity_unit_rpm), 1), "profile velocity")
            self._write(
                dxl_id, t.profile_acceleration, 4, max(int(rpm2 / t.acceleration_unit_rpm2), 1), "profile acceleration"
            )
        g = cfg.gripper
        if g is not None and cfg.set_operating_mode:
            torque, res, err = self._ph.read1ByteTxRx(self._port, g.dxl_id, g.table.torque_enable)
            self._check(res, err, "read torque", g.dxl_id)
            if not torque:
                self._write(g.dxl_id, g.table.operating_mode, 1, g.table.position_mode, "operating mode")

    def close(self) -> None:
        with self._lock:
            if self._port is None:
                return
            try:
                if self.config.torque_off_on_close:
                    self.torque(False)
            finally:
                self._port.closePort()
                self._port = None

    def _require(self) -> PortHandler:
        if self._port is None:
            raise DriverError("dynamixel driver is not connected", code="not_connected")
        return self._port

    # ------------------------------------------------------------------ joints
    def _sync_read_positions(self) -> np.ndarray:
        t = self.config.joint_table
        res = None
        for _ in range(self.config.retries + 1):
            res = self._gsr.txRxPacket()
            if res == COMM_SUCCESS:
                break
        missing = [i for i in self._ids if not self._gsr.isAvailable(i, t.present_position, 4)]
        if res != COMM_SUCCESS or missing:
            # the sync read gives up at the first silent servo: ping them one by one to name it
            missing = [i for i in self._ids if self._ph.ping(self._port, i)[1] != COMM_SUCCESS] or missing
            raise DriverError(
                f"servo(s) {missing or self._ids} did not answer the position read: {self._ph.getTxRxResult(res)}",
                code="servo_silent",
                detail={"ids": missing},
            )
        return np.array(
            [j.to_rad(_signed32(self._gsr.getData(j.dxl_id, t.present_position, 4))) for j in self.config.joints]
        )

    def _check_hardware_errors(self) -> None:
        t = self.config.joint_table
        res = self._gsr_err.txRxPacket()
        if res != COMM_SUCCESS:
            raise DriverError(
                "hardware error read failed", code="servo_silent", detail={"result": self._ph.getTxRxResult(res)}
            )
        bad = {i: self._gsr_err.getData(i, t.hardware_error, 1) for i in self._ids}
        bad = {i: v for i, v in bad.items() if v}
        if bad:
            raise DriverError(f"servo hardware error {bad}", code="servo_error", detail={"hardware_error": bad})

    def read_joints(self) -> np.ndarray:
        with self._lock:
            self._require()
            return self._sync_read_positions()

    def write_setpoint(self, q: np.ndarray) -> None:
        with self._lock:
            self._require()
            q = np.asarray(q, dtype=np.float64)
            self._gsw.clearParam()
            for j, v in zip(self.config.joints, q, strict=True):
                self._gsw.addParam(j.dxl_id, _u32_bytes(j.to_ticks(float(v))))
            res = self._gsw.txPacket()
            if res != COMM_SUCCESS:
                raise DriverError(f"sync write failed: {self._ph.getTxRxResult(res)}", code="link_failed")
            self._last_goal = q.copy()
            present = self._sync_read_positions()
            self._cycle += 1
            if self._cycle % max(self.config.error_check_every, 1) == 0:
                self._check_hardware_errors()
            lag = np.abs(present - q)
            if np.max(lag) > self.config.max_tracking_error:
                i = int(np.argmax(lag))
                raise DriverError(
                    f"joint {i + 1} lags its set-point by {lag[i]:.3f} rad",
                    code="tracking_error",
                    detail={"joint": i + 1, "id": self._ids[i], "lag_rad": float(lag[i])},
                )

    def torque(self, on: bool) -> None:
        with self._lock:
            self._require()
            ids = [(i, self.config.joint_table) for i in self._ids]
            if self.config.gripper:
                ids.append((self.config.gripper.dxl_id, self.config.gripper.table))
            if on:  # hold where the arm is: goal = present before torque comes on
                present = self._sync_read_positions()
                self._gsw.clearParam()
                for j, v in zip(self.config.joints, present, strict=True):
                    self._gsw.addParam(j.dxl_id, _u32_bytes(j.to_ticks(float(v))))
                self._gsw.txPacket()
            for dxl_id, table in ids:
                self._write(dxl_id, table.torque_enable, 1, 1 if on else 0, "torque enable")

    def stop(self) -> None:
        """Hold: write the present positions as goals."""
        with self._lock:
            self._require()
            present = self._sync_read_positions()
            self._gsw.clearParam()
            for j, v in zip(self.config.joints, present, strict=True):
                self._gsw.addParam(j.dxl_id, _u32_bytes(j.to_ticks(float(v))))
            self._gsw.txPacket()

    # ------------------------------------------------------------------ gripper
    def set_gripper(self, opening_m: float, force: float) -> None:
        g = self.config.gripper
        if g is None:
            raise DriverError("no gripper configured", code="no_gripper")
        with self._lock:
            self._require()
            self._write(g.dxl_id, g.table.goal_current, 2, g.current_ma(force), "goal current")
            self._write(g.dxl_id, g.table.goal_position, 4, g.to_ticks(opening_m), "gripper goal position")

    def read_gripper(self) -> float:
        g = self.config.gripper
        if g is None:
            raise DriverError("no gripper configured", code="no_gripper")
        with self._lock:
            self._require()
            ticks, res, err = self._retry(self._ph.read4ByteTxRx, self._port, g.dxl_id, g.table.present_position)
            self._check(res, err, "gripper position read", g.dxl_id)
            return g.to_opening(_signed32(ticks))
