"""DYNAMIXEL driver (dynamixel-sdk, Protocol 2.0): X and P series in one driver, chosen per joint by model.

Connect: ping every servo and compare the model number it reports with the configured model (a mismatch
is refused, naming the ID, the model expected and the model found); read Hardware Error Status (a servo
in error is refused, with the faults named); write the EEPROM settings while torque is off (operating
mode, homing offset, return delay); write the profiles; read the present positions, make them the goals,
and only then turn torque on, so the arm neither jumps nor falls.

Every set-point is a GroupSyncWrite of Goal Position followed by a GroupSyncRead of Present Position (one
pair per control-table layout on the bus), so a servo that stops answering is noticed within one cycle;
every ``error_check_every`` cycles Hardware Error Status is read too. Either, or a tracking error beyond
``max_tracking_error``, raises ``DriverError`` (the controller then stops the motion). ``settle`` ends a
motion: every joint must come within ``settle_tolerance`` of the last set-point, else ``tracking_error``
naming the joint and its error; it takes the bus only for each read, so a stop is never queued behind it.
E-stop (``stop``) holds: goal = present on every servo that answers, the gripper included (unless
``keep_grip``: it holds an object), torque on; a servo that cannot be held is named (``hold_failed``). A servo
that stops answering is named at once (the first one missing from an ordered sync read), then left out of
every later read, so neither the state stream nor a stop waits for it again; ``clear_faults`` takes it back.
``close`` follows the configured ``shutdown`` policy (``hold``: torque stays on; ``relax``: torque off).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np
from dynamixel_sdk import (
    COMM_SUCCESS,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)

from services.arm.drivers.base import ArmDriver
from services.arm.drivers.dynamixel.config import DynamixelConfig, JointServoConfig
from services.arm.drivers.dynamixel.control_table import ControlTable, describe_hardware_error, model_name
from services.arm.errors import DriverError

ALERT_BIT = 0x80


def _u32_bytes(v: int) -> list[int]:
    return list(int(v & 0xFFFFFFFF).to_bytes(4, "little"))


def _signed32(v: int) -> int:
    return v - (1 << 32) if v > 0x7FFFFFFF else v


@dataclass
class _Group:
    """Joints sharing one control-table layout: one sync write of goals, one sync read of positions."""

    table: ControlTable
    index: list[int]  # joint indices (0..5)
    write: GroupSyncWrite
    read: GroupSyncRead
    errors: GroupSyncRead


class DynamixelArmDriver(ArmDriver):
    name = "dynamixel"

    def __init__(self, config: DynamixelConfig | None = None):
        self.config = config or DynamixelConfig()
        self._joints: list[JointServoConfig] = list(self.config.joints)
        self._ids = [j.dxl_id for j in self._joints]
        self._port: PortHandler | None = None
        self._ph = PacketHandler(2.0)
        self._lock = threading.RLock()
        self._cycle = 0
        self._groups: list[_Group] = []
        self._last_goal: np.ndarray | None = None
        self._present = np.zeros(len(self._joints))  # last positions read (a silent servo keeps its last one)
        self._silent: dict[int, str] = {}  # id -> name of servos that stopped answering (left out of reads)
        self._suspect: dict[int, str] = {}  # missed the read in progress: named at once, before the retries
        self._preempt = threading.Event()  # a stop is waiting for the bus: readers give up their retries
        self.keep_grip = False  # the gripper holds an object: a stop leaves its grip as it is
        self.last_hold: dict = {}  # what the last stop held: joints (rad) and the gripper opening (m)
        self.servo_info: dict[int, dict] = {}  # id -> {"model", "model_number", "firmware"} read at connect

    @property
    def home_q(self) -> np.ndarray:
        return np.asarray(self.config.home, dtype=np.float64)

    def motion_caps(self) -> tuple[np.ndarray, np.ndarray]:
        """The profile velocity/acceleration every joint servo is given at connect, in rad/s and rad/s^2."""
        cfg = self.config
        vel = [j.table.rad_per_s(j.profile_velocity) if j.profile_velocity else cfg.profile_velocity
               for j in self._joints]
        acc = [j.table.rad_per_s2(j.profile_acceleration) if j.profile_acceleration else cfg.profile_acceleration
               for j in self._joints]
        return np.asarray(vel), np.asarray(acc)

    # ------------------------------------------------------------------ link
    def _check(self, result: int, error: int, what: str, dxl_id: int) -> None:
        if result != COMM_SUCCESS:
            raise DriverError(
                f"servo {dxl_id} did not answer {what}: {self._ph.getTxRxResult(result)}",
                code="servo_silent",
                detail={"id": dxl_id, "what": what},
            )
        if error & ~ALERT_BIT:
            raise DriverError(
                f"servo {dxl_id} reported an error on {what}: {self._ph.getRxPacketError(error)}",
                code="servo_error",
                detail={"id": dxl_id, "what": what, "error": int(error)},
            )

    def _retry(self, fn, *args):  # noqa: ANN001, ANN202 - any SDK call returning (..., result, error)
        for attempt in range(self.config.retries + 1):
            out = fn(*args)
            if out[-2] == COMM_SUCCESS or attempt == self.config.retries:
                return out
        return out

    def _servos(self) -> list[tuple[str, int, ControlTable]]:
        """(name, id, table) of every configured servo, joints first."""
        out = [(j.name or f"joint{k + 1}", j.dxl_id, j.table) for k, j in enumerate(self._joints)]
        g = self.config.gripper
        if g is not None:
            out.append((g.name, g.dxl_id, g.table))
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
                raise DriverError(f"cannot open {cfg.port}: {exc}", code="port_unavailable",
                                  detail={"port": cfg.port}) from exc
            if not ok:
                raise DriverError(f"cannot open {cfg.port} at {cfg.baudrate} baud", code="port_unavailable",
                                  detail={"port": cfg.port})
            self._port = port
            try:
                self._identify()
                self._make_groups()
                self._check_hardware_errors(include_gripper=True)
                self._configure_servos()
                self._hold_and_enable()
            except Exception:
                port.closePort()
                self._port = None
                raise

    def _identify(self) -> None:
        """Ping every servo; the model number it reports must be the configured model's."""
        for name, dxl_id, table in self._servos():
            model_number, res, err = self._retry(self._ph.ping, self._port, dxl_id)
            self._check(res, err, "ping", dxl_id)
            fw, res, err = self._retry(self._ph.read1ByteTxRx, self._port, dxl_id, 6)
            self._check(res, err, "firmware read", dxl_id)
            self.servo_info[dxl_id] = {"name": name, "model": model_name(model_number),
                                       "model_number": int(model_number), "firmware": int(fw)}
            if model_number != table.model_number:
                raise DriverError(
                    f"servo {dxl_id} ({name}) is a {model_name(model_number)} (model number {model_number}), "
                    f"the robot configuration expects a {table.name} (model number {table.model_number})",
                    code="model_mismatch",
                    detail={"id": dxl_id, "joint": name, "expected": table.name,
                            "expected_model_number": table.model_number, "found": model_name(model_number),
                            "found_model_number": int(model_number)},
                )

    def _make_groups(self) -> None:
        layouts: dict[tuple[int, int], _Group] = {}
        for k, j in enumerate(self._joints):
            t = j.table
            grp = layouts.get(t.layout)
            if grp is None:
                grp = layouts[t.layout] = _Group(
                    t, [], GroupSyncWrite(self._port, self._ph, t.goal_position, 4),
                    GroupSyncRead(self._port, self._ph, t.present_position, 4),
                    GroupSyncRead(self._port, self._ph, t.hardware_error, 1))
            grp.index.append(k)
            grp.read.addParam(j.dxl_id)
            grp.errors.addParam(j.dxl_id)
        self._groups = list(layouts.values())

    def _write(self, dxl_id: int, addr: int, size: int, value: int, what: str) -> None:
        fn = {1: self._ph.write1ByteTxRx, 2: self._ph.write2ByteTxRx, 4: self._ph.write4ByteTxRx}[size]
        res, err = fn(self._port, dxl_id, addr, value & ((1 << (8 * size)) - 1))
        self._check(res, err, what, dxl_id)

    def _read(self, dxl_id: int, addr: int, size: int, what: str) -> int:
        fn = {1: self._ph.read1ByteTxRx, 2: self._ph.read2ByteTxRx, 4: self._ph.read4ByteTxRx}[size]
        value, res, err = self._retry(fn, self._port, dxl_id, addr)
        self._check(res, err, what, dxl_id)
        return int(value)

    def _configure_servos(self) -> None:
        """EEPROM settings (only while torque is off) and the hardware speed/acceleration caps."""
        cfg = self.config
        entries = [(j.dxl_id, j.table, j) for j in self._joints]
        if cfg.gripper is not None:
            entries.append((cfg.gripper.dxl_id, cfg.gripper.table, cfg.gripper))
        for dxl_id, t, s in entries:
            torque_on = self._read(dxl_id, t.torque_enable, 1, "read torque")
            if not torque_on:
                if cfg.set_operating_mode:
                    self._write(dxl_id, t.operating_mode, 1, t.position_mode, "operating mode")
                if getattr(s, "homing_offset", None) is not None:
                    self._write(dxl_id, t.homing_offset, 4, s.homing_offset, "homing offset")
                if s.return_delay_time is not None:
                    self._write(dxl_id, t.return_delay_time, 1, s.return_delay_time, "return delay time")
            is_joint = s is not cfg.gripper
            vel = s.profile_velocity if s.profile_velocity is not None else (
                t.raw_velocity(cfg.profile_velocity) if is_joint else None)
            acc = s.profile_acceleration if s.profile_acceleration is not None else (
                t.raw_acceleration(cfg.profile_acceleration) if is_joint else None)
            if acc is not None:
                self._write(dxl_id, t.profile_acceleration, 4, acc, "profile acceleration")
            if vel is not None:
                self._write(dxl_id, t.profile_velocity, 4, vel, "profile velocity")

    def _sync_goals(self, q: np.ndarray, skip: set[int] | frozenset[int] = frozenset()) -> None:
        for grp in self._groups:
            grp.write.clearParam()
            for k in grp.index:
                j = self._joints[k]
                if j.dxl_id not in skip:
                    grp.write.addParam(j.dxl_id, _u32_bytes(j.to_ticks(float(q[k]))))
            if not grp.write.data_dict:
                continue
            res = grp.write.txPacket()
            if res != COMM_SUCCESS:
                raise DriverError(f"sync write failed: {self._ph.getTxRxResult(res)}", code="link_failed")

    def _hold_and_enable(self) -> None:
        """Goal = present on every servo, then torque on: the arm holds where it is, no jump."""
        present = self._sync_read_positions()
        self._sync_goals(present)
        self._last_goal = present.copy()
        g = self.config.gripper
        if g is not None:
            ticks = _signed32(self._read(g.dxl_id, g.table.present_position, 4, "gripper position read"))
            self._write(g.dxl_id, g.table.goal_position, 4, ticks, "gripper goal position")
        for _, dxl_id, table in self._servos():
            self._write(dxl_id, table.torque_enable, 1, 1, "torque enable")

    def close(self) -> None:
        with self._lock:
            if self._port is None:
                return
            try:
                if self.config.shutdown == "relax":
                    self.torque(False)
            finally:
                self._port.closePort()
                self._port = None

    def _require(self) -> PortHandler:
        if self._port is None:
            raise DriverError("dynamixel driver is not connected", code="not_connected")
        return self._port

    # ------------------------------------------------------------------ joints
    @property
    def silent_servos(self) -> dict[int, str]:
        """Servos that stopped answering (id -> name), left out of reads until ``clear_faults``."""
        return dict(self._silent)

    @property
    def suspected_silent(self) -> dict[int, str]:
        """Servos that missed an attempt of the read still in progress (its retries decide): so a state
        stream names a servo that falls silent one packet timeout after it did, not after every retry."""
        return dict(self._suspect)

    @property
    def last_present(self) -> np.ndarray:
        """The joint positions last read (a silent servo's is where it last answered)."""
        return self._present.copy()

    def _name_of(self, dxl_id: int) -> str:
        for name, i, _ in self._servos():
            if i == dxl_id:
                return name
        return str(dxl_id)

    def _mark_silent(self, ids: list[int]) -> None:
        for i in ids:
            if i not in self._silent:
                self._silent[i] = self._name_of(i)
                for grp in self._groups:
                    if i in grp.read.data_dict:
                        grp.read.removeParam(i)
                        grp.errors.removeParam(i)

    def _silent_error(self, ids: list[int], what: str = "the position read") -> DriverError:
        names = [self._silent.get(i) or self._name_of(i) for i in ids]
        return DriverError(f"servo(s) {ids} ({', '.join(names)}) did not answer {what}", code="servo_silent",
                           detail={"ids": ids, "servos": names})

    def clear_faults(self) -> None:
        """Take silent servos back into the reads (after the cause was fixed; the next read checks them)."""
        with self._lock:
            for i in list(self._silent):
                for grp in self._groups:
                    if any(self._joints[k].dxl_id == i for k in grp.index):
                        grp.read.addParam(i)
                        grp.errors.addParam(i)
            self._silent.clear()

    def _sync_read_positions(self, retries: int | None = None, strict: bool = True) -> np.ndarray:
        """Present positions of the answering joints (cached in ``_present``). A servo missing from the
        answer is named as silent (servos answer a sync read in order, so the first one missing is the one
        that did not answer) and left out from then on; ``strict``: raise ``servo_silent`` while any is."""
        retries = self.config.retries if retries is None else retries
        for grp in self._groups:
            addr = grp.table.present_position
            available: list[int] = []
            attempts = retries + 1
            while grp.read.data_dict:
                ids = list(grp.read.data_dict)
                res = None
                missing = ids[0]
                for _ in range(attempts):
                    for i in ids:  # emptied: after a failed read, the first servo with no data is the silent one
                        grp.read.data_dict[i] = []
                    res = grp.read.txRxPacket()
                    if res == COMM_SUCCESS or self._preempt.is_set():
                        break  # a stop waits for the bus: it is told what is missing, not kept waiting
                    missing = next((i for i in ids if not grp.read.data_dict[i]), ids[0])
                    self._suspect[missing] = self._name_of(missing)
                self._suspect.clear()
                if res == COMM_SUCCESS:
                    available = [i for i in ids if grp.read.isAvailable(i, addr, 4)]
                    break
                self._mark_silent([missing])
                attempts = 1  # the others, read once more without it
            for k in grp.index:
                j = self._joints[k]
                if j.dxl_id in available:
                    self._present[k] = j.to_rad(_signed32(grp.read.getData(j.dxl_id, addr, 4)))
        if strict and self._silent:
            raise self._silent_error(sorted(self._silent))
        return self._present.copy()

    def _check_hardware_errors(self, include_gripper: bool = False) -> None:
        """Hardware Error Status of every joint (and the gripper): any bit set is a typed ``servo_error``."""
        bad: dict[int, int] = {}
        for grp in self._groups:
            if not grp.errors.data_dict:
                continue
            for _ in range(self.config.retries + 1):
                res = grp.errors.txRxPacket()
                if res == COMM_SUCCESS:
                    break
            if res != COMM_SUCCESS:
                raise DriverError("hardware error read failed", code="servo_silent",
                                  detail={"result": self._ph.getTxRxResult(res)})
            for k in grp.index:
                i = self._joints[k].dxl_id
                if i in grp.errors.data_dict:
                    bad[i] = grp.errors.getData(i, grp.table.hardware_error, 1)
        g = self.config.gripper
        if include_gripper and g is not None:
            bad[g.dxl_id] = self._read(g.dxl_id, g.table.hardware_error, 1, "hardware error status")
        bad = {i: v for i, v in bad.items() if v}
        if bad:
            named = {i: describe_hardware_error(v) for i, v in bad.items()}
            text = "; ".join(f"ID {i}: {', '.join(v)}" for i, v in named.items())
            raise DriverError(f"servo hardware error: {text} (reboot the servo after fixing the cause)",
                              code="servo_error", detail={"hardware_error": bad, "faults": named})

    def read_joints(self) -> np.ndarray:
        with self._lock:
            self._require()
            return self._sync_read_positions()

    def _check_limits(self, q: np.ndarray) -> None:
        for j, v in zip(self._joints, q, strict=True):
            if j.limits is not None and not j.limits[0] <= v <= j.limits[1]:
                raise DriverError(f"{j.name or j.dxl_id} set-point {v:.3f} rad is outside its configured limits "
                                  f"{list(j.limits)}", code="joint_limit",
                                  detail={"joint": j.name, "id": j.dxl_id, "q": float(v), "limits": list(j.limits)})

    def write_setpoint(self, q: np.ndarray) -> None:
        with self._lock:
            self._require()
            q = np.asarray(q, dtype=np.float64)
            self._check_limits(q)
            self._sync_goals(q)
            self._last_goal = q.copy()
            present = self._sync_read_positions()
            self._cycle += 1
            if self._cycle % max(self.config.error_check_every, 1) == 0:
                self._check_hardware_errors()
            lag = np.abs(present - q)
            if np.max(lag) > self.config.max_tracking_error:
                raise self._tracking_error(int(np.argmax(lag)), float(lag[int(np.argmax(lag))]), "lags its set-point")

    def _tracking_error(self, k: int, err: float, what: str) -> DriverError:
        j = self._joints[k]
        name = j.name or f"joint{k + 1}"
        return DriverError(f"{name} (ID {j.dxl_id}) {what} by {err:.3f} rad", code="tracking_error",
                           detail={"joint": name, "index": k + 1, "id": j.dxl_id, "error_rad": err})

    def settle(self, q: np.ndarray | None = None, stop_event: threading.Event | None = None) -> np.ndarray:
        """Wait until every joint is within ``settle_tolerance`` of ``q`` (default: the last set-point).

        The bus is taken for each read only, never across the wait, and the wait ends at once when
        ``stop_event`` is set (returning where the arm is): a stop never queues behind a settle. A servo in
        hardware error is named as such; one that simply does not get there (stalled, blocked, torque off)
        gives ``tracking_error`` with the joint and its error."""
        cfg = self.config
        with self._lock:
            self._require()
            target = np.asarray(q if q is not None else self._last_goal, dtype=np.float64)
        deadline = time.monotonic() + cfg.settle_timeout_s
        wait = stop_event.wait if stop_event is not None else time.sleep
        while True:
            with self._lock:
                self._require()
                present = self._sync_read_positions()
            err = np.abs(present - target)
            if np.max(err) <= cfg.settle_tolerance or (stop_event is not None and stop_event.is_set()):
                return present
            if time.monotonic() > deadline:
                with self._lock:
                    self._check_hardware_errors()
                k = int(np.argmax(err))
                raise self._tracking_error(k, float(err[k]), "did not settle at its target")
            if wait(0.005) is True:
                return present

    def torque(self, on: bool) -> None:
        with self._lock:
            self._require()
            if on:  # hold where the arm is: goal = present before torque comes on
                self._hold_and_enable()
                return
            for _, dxl_id, table in self._servos():
                self._write(dxl_id, table.torque_enable, 1, 0, "torque enable")

    def stop(self) -> None:
        """Hold: goal = present on every joint that answers and on the gripper (unless ``keep_grip``), torque
        stays on. At most one retry per read, none for a servo already known silent; a servo that could not
        be held raises ``hold_failed`` naming it, after every other servo was held."""
        self._preempt.set()  # a reader retrying a silent servo gives the bus up now
        with self._lock:
            self._preempt.clear()
            self._require()
            # one retry at most (a loaded host can miss one status packet); known-silent servos are not asked
            present = self._sync_read_positions(retries=min(self.config.retries, 1), strict=False)
            unheld = dict(self._silent)
            self.last_hold = {"q": [float(v) for v in present]}
            self._sync_goals(present, skip=set(unheld))
            self._last_goal = present
            g = self.config.gripper
            if g is not None and not self.keep_grip and g.dxl_id not in unheld:
                try:
                    value, res, err = self._ph.read4ByteTxRx(self._port, g.dxl_id, g.table.present_position)
                    if res != COMM_SUCCESS and self.config.retries:
                        value, res, err = self._ph.read4ByteTxRx(self._port, g.dxl_id, g.table.present_position)
                    self._check(res, err, "gripper position read", g.dxl_id)
                    self._write(g.dxl_id, g.table.goal_position, 4, _signed32(value), "gripper hold")
                    self.last_hold["gripper_opening"] = g.to_opening(_signed32(value))
                except DriverError:
                    unheld[g.dxl_id] = g.name
        if unheld:
            servos = [{"id": i, "name": n} for i, n in sorted(unheld.items())]
            named = ", ".join(f"{n} (ID {i})" for i, n in sorted(unheld.items()))
            raise DriverError(f"the hold could not be written to {named}", code="hold_failed",
                              detail={"servos": servos})

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
            return g.to_opening(_signed32(self._read(g.dxl_id, g.table.present_position, 4, "gripper position read")))


def scan_bus(port: str, baudrate: int = 1_000_000) -> list[dict]:
    """Every servo answering a broadcast ping on ``port``: ID, model (name and number), firmware.

    For ``objscan devices``: no configuration needed, nothing written."""
    ph = PacketHandler(2.0)
    handler = PortHandler(port)
    try:
        ok = handler.openPort() and handler.setBaudRate(baudrate)
    except Exception as exc:  # pyserial raises SerialException/OSError
        raise DriverError(f"cannot open {port}: {exc}", code="port_unavailable", detail={"port": port}) from exc
    if not ok:
        raise DriverError(f"cannot open {port} at {baudrate} baud", code="port_unavailable", detail={"port": port})
    try:
        found, res = ph.broadcastPing(handler)
        if res != COMM_SUCCESS and not found:
            return []
        return [{"id": int(i), "model": model_name(int(m)), "model_number": int(m), "firmware": int(fw)}
                for i, (m, fw) in sorted(found.items())]
    finally:
        handler.closePort()
