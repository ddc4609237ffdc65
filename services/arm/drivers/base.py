"""One interface for every arm backend (LeRobot ``motors/`` style: one folder per backend with its config).

``ArmDriver`` is deliberately small: the controller above it plans, checks and times motions; a driver
only connects, reads joint positions, writes one joint set-point, drives the gripper, switches torque and
holds still on ``stop``. ``execute`` streams a planned trajectory through any driver at a fixed rate and
aborts at once when ``stop_event`` is set (an e-stop from another thread or task).
"""

from __future__ import annotations

import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from services.arm.errors import BadCommand, DriverError
from services.arm.motion import JointTrajectory
from services.arm.robot import JOINT_NAMES

# a camera-up posture clear of the table: where the twin starts, and every backend's home unless configured
HOME_Q = (0.0, -0.3, -0.9, 0.0, 1.2, 0.0)


class ArmDriver(ABC):
    """A 6-joint arm with a parallel gripper. Units: rad for joints, m for the opening, N for force."""

    name = "driver"
    joint_names = JOINT_NAMES
    read_only = False  # True: reports recorded states, refuses motion (replay)

    @property
    def home_q(self) -> np.ndarray:
        """Joint positions of the home posture (rad); backends with a configuration override it."""
        return np.asarray(HOME_Q, dtype=np.float64)

    def motion_caps(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(velocity rad/s, acceleration rad/s^2) per joint the hardware itself enforces, or None. The
        controller plans under them, so a servo's own profile never makes the arm lag its set-points."""
        return None

    def home(self) -> None:
        """Read-only backends only: go back to their first state (a moving arm goes to ``home_q`` instead)."""
        raise BadCommand(f"the {self.name} driver moves to home_q through the controller", code="bad_value")

    # the gripper holds an object: a stop leaves its grip as it is (set by the controller; stated policy)
    keep_grip = False

    def settle(self, q: np.ndarray, stop_event: threading.Event | None = None) -> np.ndarray:
        """After a motion: confirm the arm reached ``q`` and return where it is. Hardware backends wait for
        the servos (ending the wait at once when ``stop_event`` is set) and raise ``DriverError``
        (``tracking_error``) when a joint stays off; a twin that follows set-points exactly has nothing to
        wait for."""
        return self.read_joints()

    def clear_faults(self) -> None:
        """Forget servos found silent so the next read checks them again (after an e-stop reset)."""
        return None

    @abstractmethod
    def connect(self) -> None:
        """Open the link to the hardware (or twin); idempotent."""

    @abstractmethod
    def close(self) -> None:
        """Release the link; the arm holds or goes limp depending on the backend (documented there)."""

    @abstractmethod
    def read_joints(self) -> np.ndarray:
        """Present joint positions (6,), rad."""

    @abstractmethod
    def write_setpoint(self, q: np.ndarray) -> None:
        """Command joint positions (6,), rad. No checks here beyond the link: the controller checked."""

    @abstractmethod
    def set_gripper(self, opening_m: float, force: float) -> None:
        """Command the finger opening (m between the pads) with a grip force limit (N)."""

    @abstractmethod
    def read_gripper(self) -> float:
        """Present opening between the pads, m."""

    @abstractmethod
    def torque(self, on: bool) -> None:
        """Enable or disable the servos' torque."""

    @abstractmethod
    def stop(self) -> None:
        """Halt now: hold the present position, joints and gripper (unless ``keep_grip``). Never waits for a
        motion or a settle; raises ``DriverError`` (``hold_failed``, naming the servos) when the hold could
        not be written to every servo."""

    def __enter__(self) -> ArmDriver:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class ExecutionResult:
    """How a streamed motion ended."""

    completed: bool
    stopped: bool
    setpoints_sent: int
    elapsed_s: float
    q_last: np.ndarray


def execute(
    driver: ArmDriver,
    trajectory: JointTrajectory,
    rate_hz: float = 100.0,
    realtime: bool = True,
    stop_event: threading.Event | None = None,
    check: Callable[[np.ndarray, np.ndarray | None, float], object] | None = None,
    on_setpoint: Callable[[float, np.ndarray], None] | None = None,
) -> ExecutionResult:
    """Stream ``trajectory`` to ``driver`` at ``rate_hz``; real time, or as fast as the driver takes them.

    In real time, a stream that falls more than one period behind (the process was not scheduled) is
    re-anchored rather than caught up: the motion takes longer, but consecutive set-points never advance
    faster than the planned velocities, which a servo with a profile velocity cap could not follow.
    ``check(q, q_prev, dt)`` runs on each set-point before it is sent (the safety envelope's last line of
    defence). When ``stop_event`` is set the loop stops before the next set-point, calls
    ``driver.stop()`` and returns with ``stopped=True``. A driver error also calls ``driver.stop()``
    (best effort) and propagates.
    """
    if not np.isfinite(rate_hz) or rate_hz <= 0:
        raise BadCommand("rate_hz must be positive", code="bad_value")
    stop_event = stop_event or threading.Event()
    dt = 1.0 / rate_hz
    n = max(int(np.ceil(trajectory.duration * rate_hz)), 1)
    t0 = t_start = time.perf_counter()
    q_prev: np.ndarray | None = None
    sent = 0
    try:
        for i in range(n + 1):
            if realtime:
                delay = t0 + i * dt - time.perf_counter()
                if delay > 0 and stop_event.wait(delay):
                    break
                if delay < -dt:  # the stream stalled (a loaded machine): resume the trajectory from here at
                    t0 -= delay  # its own pace; catching up would send set-points faster than the servos go
            if stop_event.is_set():
                break
            q = trajectory.at(min(i * dt, trajectory.duration))[0]
            if check is not None:
                check(q, q_prev, dt)
            driver.write_setpoint(q)
            sent += 1
            q_prev = q
            if on_setpoint is not None:
                on_setpoint(i * dt, q)
    except DriverError:
        try:
            driver.stop()
        except DriverError:
            pass
        raise
    stopped = stop_event.is_set() and sent < n + 1
    if stopped:  # hold again: a set-point may have gone out after the e-stop's own hold
        try:
            driver.stop()
        except DriverError:  # the e-stop that set the event reports its own hold
            pass
    q_last = q_prev if q_prev is not None else trajectory.q_start
    return ExecutionResult(not stopped, stopped, sent, time.perf_counter() - t_start, np.asarray(q_last))
