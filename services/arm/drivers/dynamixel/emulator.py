"""An emulated DYNAMIXEL bus on a pseudo-terminal: real Protocol 2.0 packets, servos with a control table.

``DynamixelBusEmulator`` opens a pty pair; the driver (or the DYNAMIXEL Wizard, or any SDK program)
opens ``emulator.port`` like a U2D2 at ``/dev/ttyUSB0``. A thread parses instruction packets (CRC
checked, byte stuffing undone) and answers like DYNAMIXEL-P (PH54/PH42/PM54/PM42), X-series servos and an
RH-P12-RN(A) gripper, each with its own control table (``control_table.py``): PING (model number and
firmware), READ, WRITE, SYNC READ, SYNC WRITE, REBOOT. Each servo keeps its table in memory; with torque
on, Present Position follows Goal Position at Profile Velocity (or at once when none is set); Homing
Offset shifts Present Position as on the real servo. The default bus is the PAPRAS one built from the
robot configuration (``servos_for``), standing at the configuration's home posture.

Faults can be injected per servo (``silent``: never answers; ``alert``: hardware error bits, reported in
every status packet and in Hardware Error Status; ``stalled``: answers but never moves; ``block_at``: the
position stops there, as fingers closing on an object; ``block_short``: an obstruction keeps the servo that
many pulses short of whatever goal it is given, until released) so tests can check that the driver stops a
motion with a typed error. ``inject``/``release`` change them while the bus runs; an emulator started with a
``fault_file`` (``FAULT_FILE_ENV`` for one started inside the arm service) re-reads that JSON file whenever it
changes, so a test or ``objscan bench estop`` in another process can block a joint or silence a servo. Only
the emulator reads it: nothing on a real bus does. Every instruction packet received is kept in ``log``.

Run it for manual work: ``python -m services.arm.drivers.dynamixel emulate``.
"""

from __future__ import annotations

import json
import math
import os
import pty
import select
import struct
import threading
import time
import tty
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from services.arm.drivers.dynamixel import protocol as p

if TYPE_CHECKING:
    from services.arm.drivers.dynamixel.config import DynamixelConfig
from services.arm.drivers.dynamixel.control_table import RH_P12_RN_A, X_SERIES, ControlTable


@dataclass
class EmulatedServo:
    """One servo: an ID, a control-table layout and 1 KiB of table memory."""

    dxl_id: int
    table: ControlTable = X_SERIES
    present_position: int | None = None  # default: the table's 0 rad
    max_position: int | None = None  # default: the table's full range
    min_position: int | None = None
    firmware: int = 46
    homing_offset: int = 0
    silent: bool = False
    alert: int = 0  # Hardware Error Status bits (0 = healthy)
    stalled: bool = False  # answers, takes goals, never moves (a blocked or broken joint)
    block_at: int | None = None  # the position cannot pass this value (fingers closed on an object)
    block_short: int | None = None  # an obstruction: stops this many pulses short of any goal (None: free)
    max_ticks_per_s: float = 0.0  # mechanical speed cap (0 = none), e.g. the gripper's 75 mm/s
    memory: bytearray = field(default_factory=lambda: bytearray(1024))

    def __post_init__(self) -> None:
        t = self.table
        half = t.ticks_per_rev // 2
        if self.present_position is None:
            self.present_position = t.center_tick
        if self.max_position is None:
            self.max_position = t.center_tick + half - 1 if t.center_tick else half
        if self.min_position is None:
            self.min_position = 0 if t.center_tick else -half
        struct.pack_into("<H", self.memory, 0, t.model_number)
        struct.pack_into("<i", self.memory, t.homing_offset, self.homing_offset)
        self.memory[6] = self.firmware
        self.memory[7] = self.dxl_id
        self.memory[t.operating_mode] = t.position_mode
        struct.pack_into("<i", self.memory, t.max_position_limit, self.max_position)
        struct.pack_into("<i", self.memory, t.min_position_limit, self.min_position)
        struct.pack_into("<i", self.memory, t.goal_position, self.present_position)
        self._position = float(self.present_position)
        self._sync_present()

    # -- registers
    def _i32(self, addr: int) -> int:
        return struct.unpack_from("<i", self.memory, addr)[0]

    @property
    def torque_on(self) -> bool:
        return bool(self.memory[self.table.torque_enable])

    @property
    def goal_position(self) -> int:
        return self._i32(self.table.goal_position)

    def _sync_present(self) -> None:
        struct.pack_into("<i", self.memory, self.table.present_position, int(round(self._position)))
        self.memory[self.table.hardware_error] = self.alert & 0xFF

    def read(self, addr: int, length: int) -> tuple[int, bytes]:
        if addr < 0 or length < 0 or addr + length > len(self.memory):
            return p.ERR_DATA_RANGE, b""
        self._sync_present()
        return 0, bytes(self.memory[addr : addr + length])

    def write(self, addr: int, data: bytes) -> int:
        t = self.table
        if addr < 0 or addr + len(data) > len(self.memory):
            return p.ERR_DATA_RANGE
        if addr < t.eeprom_end and self.torque_on:
            return p.ERR_ACCESS  # EEPROM is locked while torque is on
        if addr <= t.homing_offset < addr + len(data) and len(data) >= t.homing_offset - addr + 4:
            new = struct.unpack_from("<i", data, t.homing_offset - addr)[0]
            self._position += new - self._i32(t.homing_offset)  # Present Position = actual + Homing Offset
        if addr <= t.goal_position < addr + len(data) and len(data) >= t.goal_position - addr + 4:
            goal = struct.unpack_from("<i", data, t.goal_position - addr)[0]
            lo, hi = self._i32(t.min_position_limit), self._i32(t.max_position_limit)
            if not lo <= goal <= hi:
                return p.ERR_DATA_LIMIT
        self.memory[addr : addr + len(data)] = data
        return 0

    def status_error(self) -> int:
        return p.ERR_ALERT if self.alert else 0

    def step(self, dt: float) -> None:
        """Move Present Position towards Goal Position (torque on, no alert)."""
        if not self.torque_on or self.alert or self.stalled:
            return
        goal = float(self.goal_position)
        if self.block_at is not None and min(self._position, goal) <= self.block_at <= max(self._position, goal):
            goal = float(self.block_at)
        if self.block_short is not None:  # pushes towards the goal, never gets nearer than block_short
            d = goal - self._position
            if abs(d) <= self.block_short:
                return
            goal -= math.copysign(self.block_short, d)
        rate = float("inf")
        vel_raw = struct.unpack_from("<I", self.memory, self.table.profile_velocity)[0]
        if vel_raw and self.table is not RH_P12_RN_A:
            rate = vel_raw * self.table.velocity_unit_rpm / 60.0 * self.table.ticks_per_rev  # ticks/s
        if self.max_ticks_per_s:
            rate = min(rate, self.max_ticks_per_s)
        d = goal - self._position
        self._position = goal if abs(d) <= rate * dt else self._position + (rate * dt if d > 0 else -rate * dt)


def xm_arm_servos(ids: tuple[int, ...] = (1, 2, 3, 4, 5, 6)) -> list[EmulatedServo]:
    return [EmulatedServo(i, X_SERIES) for i in ids]


def servos_for(config: DynamixelConfig | None = None, q: Sequence[float] | None = None,
               opening: float | None = None) -> list[EmulatedServo]:
    """The bus a robot configuration describes (default: PAPRAS), standing at ``q`` (default: its home).

    Each joint servo is of the configured model with the configured homing offset already in its EEPROM
    (as on an arm set up once), so the driver reads ``q`` back exactly."""
    from services.arm.drivers.dynamixel.config import DynamixelConfig

    config = config or DynamixelConfig()
    q = config.home if q is None else q
    out = [EmulatedServo(j.dxl_id, j.table, present_position=j.to_ticks(float(v)), homing_offset=j.homing_offset or 0,
                         firmware=45 if j.table.center_tick == 0 else 46)
           for j, v in zip(config.joints, q, strict=True)]
    if config.gripper is not None:
        ticks = config.gripper.to_ticks(opening) if opening is not None else 0
        out.append(rh_p12_rn_gripper(config.gripper.dxl_id, ticks))
    return out


def rh_p12_rn_gripper(dxl_id: int = 7, present_position: int = 0) -> EmulatedServo:
    # closes its 106 mm stroke (740 pulses) at about 75 mm/s, as the e-manual states
    return EmulatedServo(
        dxl_id,
        RH_P12_RN_A,
        present_position=present_position,
        max_position=1150,
        min_position=0,
        firmware=12,
        max_ticks_per_s=740 / 1.4,
    )


FAULT_FILE_ENV = "OBJSCAN_EMULATED_BUS_FAULTS"
FAULTS = ("silent", "block_short_rad")


def write_faults(path: str | os.PathLike[str], faults: dict) -> None:
    """Publish ``faults`` (``{id: {"silent": .., "block_short_rad": ..}}``) to an emulator's fault file
    atomically, so the bus never reads half of it."""
    from common.atomic import atomic_write_bytes

    atomic_write_bytes(path, json.dumps({str(k): v for k, v in _check_faults(faults).items()}).encode())


def _check_faults(faults: dict) -> dict[int, dict]:
    """``{id: {"silent": bool, "block_short_rad": float | None}}`` with integer IDs; unknown names refused."""
    out: dict[int, dict] = {}
    for key, spec in faults.items():
        if not isinstance(spec, dict) or set(spec) - set(FAULTS):
            raise ValueError(f"servo {key}: faults are a mapping of {', '.join(FAULTS)}, got {spec!r}")
        out[int(key)] = spec
    return out


class DynamixelBusEmulator:
    """Servos behind a pty; ``port`` is the device path to open."""

    def __init__(self, servos: list[EmulatedServo] | None = None, tick_s: float = 0.002,
                 fault_file: str | os.PathLike[str] | None = None):
        servos = servos if servos is not None else servos_for()
        self.servos = {s.dxl_id: s for s in servos}
        self.tick_s = tick_s
        self.fault_file = os.fspath(fault_file) if fault_file else None
        self._fault_mtime: tuple[int, int] | None = None
        self._fault_checked = 0.0
        self.log: deque[p.Packet] = deque(maxlen=200_000)  # bounded: a long HIL run streams at 100 Hz
        self.crc_errors = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._master, self._slave = pty.openpty()
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self._thread = threading.Thread(target=self._run, name="dxl-emulator", daemon=True)

    def start(self) -> DynamixelBusEmulator:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass

    def __enter__(self) -> DynamixelBusEmulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def packets(self, instruction: int | None = None) -> list[p.Packet]:
        with self._lock:
            return [k for k in self.log if instruction is None or k.instruction == instruction]

    def snapshot(self) -> dict[int, tuple[int, int]]:
        """(present, goal) position of every servo, read consistently (the bus's physical state)."""
        with self._lock:
            out = {}
            for i, s in self.servos.items():
                s._sync_present()
                out[i] = (s._i32(s.table.present_position), s.goal_position)
            return out

    def set_block(self, dxl_id: int, position: int | None) -> None:
        """Make ``dxl_id`` stop at ``position`` (None: free), e.g. fingers meeting an object."""
        with self._lock:
            self.servos[dxl_id].block_at = position

    def inject(self, dxl_id: int, silent: bool | None = None, block_short_rad: float | None = None) -> None:
        """Silence ``dxl_id`` (it answers nothing), or put an obstruction ``block_short_rad`` short of any
        goal it is given; ``release`` undoes both."""
        with self._lock:
            s = self.servos[dxl_id]
            if silent is not None:
                s.silent = bool(silent)
            if block_short_rad is not None:
                s.block_short = int(round(abs(block_short_rad) * s.table.ticks_per_rev / (2 * math.pi)))

    def release(self, dxl_id: int) -> None:
        """The servo answers again and nothing obstructs it (its goal is unchanged: it moves there now)."""
        with self._lock:
            s = self.servos[dxl_id]
            s.silent, s.block_short = False, None

    def apply_faults(self, faults: dict) -> None:
        """Make the bus's injected faults exactly ``faults`` (``{id: {"silent": .., "block_short_rad": ..}}``;
        a servo not named is released)."""
        wanted = _check_faults(faults)
        for dxl_id in self.servos:
            self.release(dxl_id)
            spec = wanted.get(dxl_id, {})
            if spec:
                self.inject(dxl_id, silent=spec.get("silent"), block_short_rad=spec.get("block_short_rad"))

    def _poll_fault_file(self, now: float) -> None:
        """Every 5 ms at most: when the fault file changed, apply it (a missing file: no faults)."""
        if self.fault_file is None or now - self._fault_checked < 0.005:
            return
        self._fault_checked = now
        try:
            st = os.stat(self.fault_file)
            mtime = (st.st_ino, st.st_mtime_ns)  # a file replaced by rename is a new inode
        except OSError:
            mtime = None
        if mtime == self._fault_mtime:
            return
        self._fault_mtime = mtime
        try:
            text = "{}" if mtime is None else Path(self.fault_file).read_text() or "{}"
            faults = json.loads(text)
            self.apply_faults(faults)
        except (OSError, ValueError):  # half-written: the next change is read again
            self._fault_mtime = None

    def clear_log(self) -> None:
        with self._lock:
            self.log.clear()

    # -- the bus
    def _run(self) -> None:
        buf = bytearray()
        last = time.perf_counter()
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._master], [], [], self.tick_s)
            except (OSError, ValueError):
                return
            now = time.perf_counter()
            self._poll_fault_file(now)
            with self._lock:
                for s in self.servos.values():
                    s.step(now - last)
            last = now
            if not ready:
                continue
            try:
                chunk = os.read(self._master, 4096)
            except OSError:
                return
            buf.extend(chunk)
            for pkt in p.parse_packets(buf):
                reply = self._handle(pkt)
                if reply:
                    try:
                        os.write(self._master, reply)
                    except OSError:
                        return

    def _handle(self, pkt: p.Packet) -> bytes:
        with self._lock:
            self.log.append(pkt)
            if not pkt.crc_ok:
                self.crc_errors += 1
                s = self.servos.get(pkt.dxl_id)
                return p.build_status(pkt.dxl_id, p.ERR_CRC) if s and not s.silent else b""
            ins, prm = pkt.instruction, pkt.params
            if ins == p.SYNC_WRITE:
                return self._sync_write(prm)
            if ins == p.SYNC_READ:
                return self._sync_read(prm)
            targets = (
                list(self.servos.values())
                if pkt.dxl_id == p.BROADCAST_ID
                else ([self.servos[pkt.dxl_id]] if pkt.dxl_id in self.servos else [])
            )
            out = b""
            for s in targets:
                reply = self._single(s, ins, prm)
                if s.silent or (pkt.dxl_id == p.BROADCAST_ID and ins != p.PING):
                    continue  # silent servos never answer; broadcasts get no status, except PING
                out += reply
            return out

    def _single(self, s: EmulatedServo, ins: int, prm: bytes) -> bytes:
        if ins == p.PING:
            return p.build_status(s.dxl_id, s.status_error(), struct.pack("<HB", s.table.model_number, s.firmware))
        if ins == p.READ:
            if len(prm) != 4:
                return p.build_status(s.dxl_id, p.ERR_DATA_LENGTH)
            addr, length = struct.unpack("<HH", prm)
            err, data = s.read(addr, length)
            return p.build_status(s.dxl_id, err or s.status_error(), data)
        if ins == p.WRITE:
            if len(prm) < 3:
                return p.build_status(s.dxl_id, p.ERR_DATA_LENGTH)
            addr = struct.unpack_from("<H", prm)[0]
            err = s.write(addr, prm[2:])
            return p.build_status(s.dxl_id, err or s.status_error())
        if ins == p.REBOOT:
            s.alert = 0
            s.memory[s.table.torque_enable] = 0
            return p.build_status(s.dxl_id, 0)
        return p.build_status(s.dxl_id, p.ERR_INSTRUCTION)

    def _sync_write(self, prm: bytes) -> bytes:
        if len(prm) < 4:
            return b""
        addr, length = struct.unpack_from("<HH", prm)
        body = prm[4:]
        for k in range(0, len(body) - length, length + 1):
            s = self.servos.get(body[k])
            if s is not None and not s.alert:
                s.write(addr, body[k + 1 : k + 1 + length])
        return b""

    def _sync_read(self, prm: bytes) -> bytes:
        if len(prm) < 5:
            return b""
        addr, length = struct.unpack_from("<HH", prm)
        out = b""
        for dxl_id in prm[4:]:
            s = self.servos.get(dxl_id)
            if s is None or s.silent:
                continue
            err, data = s.read(addr, length)
            out += p.build_status(dxl_id, err or s.status_error(), data)
        return out
