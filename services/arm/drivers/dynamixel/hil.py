"""Hardware in the loop without hardware: the real DYNAMIXEL driver on an emulated bus that drives the twin.

``EmulatedBusDriver`` is ``DynamixelArmDriver`` unchanged (every servo read and write goes through
dynamixel-sdk, as packets on a pty) plus the bus it talks to: a ``DynamixelBusEmulator`` of the servos
the robot configuration describes (PAPRAS: DYNAMIXEL-P). ``BusTwinBridge`` plays physics for that bus:

- the servos' *present* positions (where the emulated motors are, not what was commanded) are sent to the
  digital twin through the sim backend's twin link, at up to ``rate_hz`` and once more, synchronously,
  when a motion has settled, so the twin renders from where the servos stopped;
- a gripper command is first put to the twin (the world's physics: where do fingers closing here stop?),
  and the width the twin's fingers stop at (on the object, or fully closed on a miss) becomes an obstacle
  for the emulated gripper servo; then the driver writes the goal over the bus as always, the servo
  stalls at the obstacle and the controller detects the grasp from the stalled position, as on hardware.

Faults are injected through the emulator's fault file (``OBJSCAN_EMULATED_BUS_FAULTS``, see
``emulator.py``). At start the bus stands where the twin says the arm is (or at the home posture), like an arm that was
switched on where it stood.
"""

from __future__ import annotations

import logging
import os
import threading

import numpy as np
from dynamixel_sdk import port_handler

from common.log import event
from services.arm.drivers.base import ArmDriver
from services.arm.drivers.dynamixel import protocol as p
from services.arm.drivers.dynamixel.config import DynamixelConfig
from services.arm.drivers.dynamixel.driver import DynamixelArmDriver
from services.arm.drivers.dynamixel.emulator import FAULT_FILE_ENV, DynamixelBusEmulator, servos_for
from services.arm.errors import DriverError

log = logging.getLogger("objscan.arm")


class BusTwinBridge:
    """Mirror an emulated bus into the twin (``twin``: a connected-on-start sim driver, e.g. the twin link)."""

    def __init__(self, config: DynamixelConfig, twin: ArmDriver, rate_hz: float = 30.0):
        self.config = config
        self.twin = twin
        self.period = 1.0 / rate_hz
        self.emulator: DynamixelBusEmulator | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._push_lock = threading.Lock()
        self._last_q: np.ndarray | None = None
        self.sent = 0
        self.error: BaseException | None = None

    def start(self) -> str:
        """Connect to the twin, put the emulated servos where the twin has the arm, start mirroring; the
        bus's port path is returned."""
        self.twin.connect()
        q0, opening0 = self.twin.read_joints(), self.twin.read_gripper()
        # faults (a blocked joint, a silent servo) come from a file a test or the bench names, if any
        self.emulator = DynamixelBusEmulator(servos_for(self.config, q0, opening0),
                                             fault_file=os.environ.get(FAULT_FILE_ENV) or None).start()
        self._last_q = np.asarray(q0, dtype=np.float64)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="bus-twin-bridge", daemon=True)
        self._thread.start()
        return self.emulator.port

    def _joints(self) -> np.ndarray:
        assert self.emulator is not None
        snap = self.emulator.snapshot()
        return np.array([j.to_rad(snap[j.dxl_id][0]) for j in self.config.joints])

    def push(self, force: bool = False) -> None:
        """Send the servos' present joints to the twin (when they moved, or always with ``force``)."""
        with self._push_lock:
            q = self._joints()
            if force or self._last_q is None or np.max(np.abs(q - self._last_q)) > 1e-7:
                self.twin.write_setpoint(q)
                self._last_q = q
                self.sent += 1

    def prepare_gripper(self, opening_m: float, force_n: float) -> None:
        """Before a gripper goal goes over the bus: the twin (joints brought up to date first) says where
        the fingers stop; the emulated gripper servo is blocked there when that is short of the goal."""
        g = self.config.gripper
        assert g is not None and self.emulator is not None
        self.push(force=True)
        closing = opening_m < self.twin.read_gripper() - 1e-4
        self.twin.set_gripper(opening_m, force_n)
        reached = self.twin.read_gripper()
        blocked = closing and reached > opening_m + 1e-4
        self.emulator.set_block(g.dxl_id, g.to_ticks(reached) if blocked else None)

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            try:
                self.push()
            except Exception as exc:  # the twin went away for good: the next settle reports it
                self.error = exc
                log.warning("bus-to-twin bridge: %r", exc)

    def flush(self) -> None:
        """Synchronously bring the twin to the servos' present state (after a motion settled)."""
        self.push(force=True)
        if self.error is not None:
            err, self.error = self.error, None
            raise DriverError(f"the twin did not take the emulated bus's joints: {err}", code="link_failed")

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self.emulator is not None:
            self.emulator.stop()
            self.emulator = None
        self.twin.close()


class EmulatedBusDriver(DynamixelArmDriver):
    """The DYNAMIXEL driver on its own emulated bus (``BusTwinBridge``); behaves as on hardware."""

    name = "dynamixel"

    def __init__(self, config: DynamixelConfig, twin: ArmDriver, rate_hz: float = 30.0):
        super().__init__(config)
        # the emulator shares this process (and its GIL) with the planner and the twin link: on a loaded
        # machine a status packet can miss the SDK's ~34 ms timeout, which a real bus would not; retry more
        self.config.retries = max(self.config.retries, 4)
        # and the SDK's packet timeout (2 x its 16 ms FTDI latency constant + 2 ms) is widened: only this
        # process talks to an emulated bus, no real one
        port_handler.LATENCY_TIMER = max(port_handler.LATENCY_TIMER, 50)
        self.bridge = BusTwinBridge(self.config, twin, rate_hz)

    def connect(self) -> None:
        if self._port is not None:
            return
        self.config.port = self.bridge.start()
        try:
            super().connect()
        except Exception:
            self.bridge.stop()
            raise
        event(log, "dynamixel driver on an emulated bus driving the twin", port=self.config.port,
              servos={i: v["model"] for i, v in self.servo_info.items()})

    @property
    def last_gripper(self) -> object:
        """The twin's last gripper answer (its ``reason``: grasped, missed, ...), as the sim backend has it."""
        return getattr(self.bridge.twin, "last_gripper", None)

    def set_gripper(self, opening_m: float, force: float) -> None:
        if self.config.gripper is not None:
            self.bridge.prepare_gripper(opening_m, force)
        super().set_gripper(opening_m, force)

    def settle(self, q: np.ndarray | None = None, stop_event: threading.Event | None = None) -> np.ndarray:
        present = super().settle(q, stop_event)
        self.bridge.flush()
        return present

    def close(self) -> None:
        emu = self.bridge.emulator
        try:
            super().close()
        finally:
            if emu is not None:
                event(log, "emulated bus closed", sync_writes=len(emu.packets(p.SYNC_WRITE)),
                      sync_reads=len(emu.packets(p.SYNC_READ)), twin_updates=self.bridge.sent)
            self.bridge.stop()
