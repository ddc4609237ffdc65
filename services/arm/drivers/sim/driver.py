"""Sim driver: streams joint set-points to the digital twin through an injected ``send`` callable.

The service face wires ``send(q, gripper_opening)`` to Zenoh ``objscan/{robot}/sim/joints``; tests pass a
list's ``append``. The twin follows set-points exactly, so ``read_joints`` reports the last one sent
unless a ``read`` callable (the twin's reported state) is given.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np

from services.arm.drivers.base import ArmDriver
from services.arm.drivers.sim.config import SimDriverConfig
from services.arm.errors import DriverError


class SimArmDriver(ArmDriver):
    name = "sim"

    def __init__(
        self,
        send: Callable[[np.ndarray, float], None] | None = None,
        config: SimDriverConfig | None = None,
        read: Callable[[], np.ndarray] | None = None,
    ):
        self.config = config or SimDriverConfig()
        self._send = send
        self._read = read
        self._q = np.asarray(self.config.initial_q, dtype=np.float64).copy()
        self._opening = float(self.config.initial_opening)
        self._force = 0.0
        self._torque = False
        self._connected = False
        self._lock = threading.Lock()

    @property
    def home_q(self) -> np.ndarray:
        return np.asarray(self.config.initial_q, dtype=np.float64)

    def connect(self) -> None:
        self._connected = True
        self._torque = True

    def close(self) -> None:
        self._connected = False

    def _require(self) -> None:
        if not self._connected:
            raise DriverError("sim driver is not connected", code="not_connected")

    def _publish(self) -> None:
        if self._send is not None:
            try:
                self._send(self._q.copy(), self._opening)
            except Exception as exc:  # the transport failed: the motion must stop
                raise DriverError(f"sending to the twin failed: {exc}", code="link_failed") from exc

    def read_joints(self) -> np.ndarray:
        self._require()
        if self._read is not None:
            return np.asarray(self._read(), dtype=np.float64).copy()
        with self._lock:
            return self._q.copy()

    def write_setpoint(self, q: np.ndarray) -> None:
        self._require()
        if not self._torque:
            raise DriverError("torque is off", code="torque_off")
        with self._lock:
            self._q = np.asarray(q, dtype=np.float64).copy()
            self._publish()

    def set_gripper(self, opening_m: float, force: float) -> None:
        self._require()
        with self._lock:
            self._opening, self._force = float(opening_m), float(force)
            self._publish()

    def read_gripper(self) -> float:
        self._require()
        return self._opening

    def torque(self, on: bool) -> None:
        self._require()
        self._torque = bool(on)

    def stop(self) -> None:
        # the twin holds wherever the last set-point put it
        return None
