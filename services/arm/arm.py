"""``ArmController``: the arm's whole behaviour without any transport (the service face adds Zenoh).

It holds the driver, the kinematics, the collision world (table + an optional object box the caller
sets) and the safety envelope. Every move is planned, then checked in full (envelope: limits, workspace,
TCP height; collisions sampled along the motion) and only then streamed to the driver, so a refused
command never moves the arm. Moves block until finished or failed (the service face runs them in an
executor); ``estop()`` from any other thread halts a running motion before its next set-point (or ends
its settle check at once), holds every servo where it is, the gripper too, and latches until
``reset_estop()``; when the hold could not be written to some servo the e-stop latches as *failed* and
says which. Every fault that ends a move (tracking error, hardware error, silent servo, timeout) leaves
the arm holding where it is, and ``state()`` says what happened (``fault``). ``state(read=False)`` touches
no bus: the service's state stream reads the bus in a thread of its own.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin

from services.arm.collision import CollisionConfig, CollisionWorld
from services.arm.drivers.base import ArmDriver, execute
from services.arm.errors import ArmError, BadCommand, DriverError, EnvelopeError, MotionStopped
from services.arm.kinematics import Kinematics, KinematicsConfig, check_transform
from services.arm.motion import (
    JointTrajectory,
    LinePathConfig,
    MotionLimits,
    plan_joint_motion,
    plan_linear_motion,
)
from services.arm.safety import SafetyConfig, SafetyEnvelope


@dataclass
class ArmConfig:
    """Everything the controller needs; defaults are the simulated cell's."""

    kinematics: KinematicsConfig = field(default_factory=KinematicsConfig)
    limits: MotionLimits = field(default_factory=MotionLimits)
    collision: CollisionConfig = field(default_factory=CollisionConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    line: LinePathConfig = field(default_factory=LinePathConfig)
    rate_hz: float = 100.0  # set-point stream rate
    realtime: bool = True  # False: stream as fast as the driver accepts (sim, tests)
    default_gripper_force: float = 40.0  # N
    gripper_tolerance: float = 0.002  # m: opening reached
    gripper_timeout_s: float = 3.0
    gripper_stall_s: float = 0.3  # no progress for this long = fingers closed on the object


class ArmController:
    """Plans, checks and executes arm and gripper commands through one ``ArmDriver``."""

    def __init__(self, driver: ArmDriver, config: ArmConfig | None = None, kinematics: Kinematics | None = None):
        self.config = config or ArmConfig()
        caps = driver.motion_caps()
        if caps is not None:  # plan with margin under the servos' own profile limits
            self.config = replace(self.config, limits=self.config.limits.capped(0.95 * caps[0], 0.95 * caps[1]))
        self.driver = driver
        self.kinematics = kinematics or Kinematics(self.config.kinematics)
        self.collision = CollisionWorld(self.kinematics, self.config.collision)
        self.safety = SafetyEnvelope(self.kinematics, self.config.safety)
        self.safety.check_limits_fit(self.config.limits)
        self._motion_lock = threading.Lock()
        self._stop = threading.Event()
        self._estopped = False  # latched (held or failed) until reset
        self._estop_failure: dict | None = None  # the servos the e-stop's hold did not reach
        self._fault: dict | None = None  # what ended the last move, when a fault did
        self._gripper_busy = False
        self._moving = False
        self._q = np.zeros(6)
        self._opening = 0.0
        self._state_data = self.kinematics.model.createData()  # state() runs beside a planning thread
        self._state_lock = threading.Lock()

    # ------------------------------------------------------------------ lifecycle
    def connect(self) -> None:
        self.driver.connect()
        self._q = self.driver.read_joints()
        self._opening = self.driver.read_gripper()

    def close(self) -> None:
        self.driver.close()

    def __enter__(self) -> ArmController:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ e-stop
    def estop(self) -> dict:
        """Halt now (from any thread) and refuse motion until ``reset_estop``: the streaming loop stops
        before its next set-point, a settle check ends, and the hold (goal = present on every servo, the
        gripper included unless it holds an object) is written here, not left to the motion thread.

        Raises ``DriverError`` (``estop_failed``, naming the servos) when the hold could not be written to
        every servo; the e-stop then stays latched as failed (``estopped`` is False, ``estop_status`` says
        ``failed``). Returns what the hold read, when the driver says (``q``, ``gripper_opening``)."""
        self._estopped = True
        self._stop.set()
        try:
            self.driver.stop()
        except (DriverError, ArmError) as exc:
            self._estop_failure = {"code": exc.code, "message": exc.message, **exc.detail}
            raise DriverError(f"emergency stop NOT confirmed: {exc.message}", code="estop_failed",
                              detail=dict(exc.detail)) from exc
        self._estop_failure = None
        return dict(getattr(self.driver, "last_hold", None) or {})

    def reset_estop(self) -> None:
        """Clear a latched stop (held or failed) and any fault: silent servos are checked again."""
        self._estopped = False
        self._estop_failure = None
        self._fault = None
        self._stop.clear()
        self.driver.clear_faults()

    @property
    def estopped(self) -> bool:
        """True only when an e-stop is latched and its hold reached every servo."""
        return self._estopped and self._estop_failure is None

    @property
    def estop_status(self) -> str:
        """``""`` (not latched), ``held`` or ``failed`` (the hold did not reach every servo)."""
        if not self._estopped:
            return ""
        return "failed" if self._estop_failure is not None else "held"

    @property
    def fault(self) -> dict | None:
        """What ended the last move or the e-stop's failure (code, message, the servo named), or None."""
        if self._estop_failure is not None:
            return {**self._estop_failure, "code": "estop_failed"}
        if self._fault is not None:
            return dict(self._fault)
        suspect = getattr(self.driver, "suspected_silent", None)
        if suspect:  # a read in progress is retrying these: named now, confirmed (or cleared) by its end
            return {"code": "servo_silent", "message": "servo(s) did not answer the read in progress (retrying)",
                    "ids": sorted(suspect), "servos": [suspect[i] for i in sorted(suspect)], "confirmed": False}
        return None

    def _hold_after_fault(self, exc: ArmError) -> None:
        """A fault ended a move: hold every servo where it is (no servo keeps a goal it was not asked to
        hold) and remember what happened for ``state()``."""
        self._fault = {"code": exc.code, "message": exc.message, **exc.detail, "stamp": time.time()}
        try:
            self.driver.stop()
        except (DriverError, ArmError) as hold_exc:
            self._fault["hold_failed"] = hold_exc.detail.get("servos", hold_exc.message)
        present = getattr(self.driver, "last_present", None)
        if present is not None:
            self._q = np.asarray(present, dtype=np.float64)

    # ------------------------------------------------------------------ state
    def refresh(self) -> None:
        """Read where the arm and the gripper are (the bus; not while a motion streams). A servo that does
        not answer is recorded as a fault naming it; the others' positions are still taken."""
        if self._moving:
            return
        try:
            self._q = self.driver.read_joints()
        except (DriverError, ArmError) as exc:
            if self._fault is None or self._fault.get("code") != exc.code:
                self._fault = {"code": exc.code, "message": exc.message, **exc.detail, "stamp": time.time()}
            present = getattr(self.driver, "last_present", None)
            if present is not None:
                self._q = np.asarray(present, dtype=np.float64)
        if not self._gripper_busy:
            try:
                self._opening = self.driver.read_gripper()
            except (DriverError, ArmError):
                pass

    def state(self, read: bool = True) -> dict:
        """q, gripper opening, TCP and camera poses in base, moving/estop flags and the last fault.
        ``read``: read the bus first (``refresh``); never while moving."""
        if read:
            self.refresh()
        q = self._q.copy()
        kin = self.kinematics
        with self._state_lock:
            pin.forwardKinematics(kin.model, self._state_data, q)
            Tg = pin.updateFramePlacement(kin.model, self._state_data, kin.frame_id("gripper")).homogeneous
            Tc = pin.updateFramePlacement(kin.model, self._state_data, kin.frame_id("camera")).homogeneous
        return {
            "names": list(kin.joint_names),
            "q": q,
            "gripper_opening": float(self._opening),
            "T_base_gripper": Tg,
            "T_base_camera": Tc,
            "moving": self._moving,
            "estopped": self.estopped,
            "estop": self.estop_status,
            "fault": self.fault,
            "stamp": time.time(),
        }

    # ------------------------------------------------------------------ planning (no motion)
    def _current_q(self) -> np.ndarray:
        self._q = self.driver.read_joints()
        return self._q.copy()

    def plan_joints(self, q: np.ndarray, speed_scale: float = 1.0) -> JointTrajectory:
        q_goal = self.safety.check_joints(q)
        return plan_joint_motion(self._current_q(), q_goal, self.config.limits, speed_scale)

    def _start_q(self, q_start: np.ndarray | None) -> np.ndarray:
        """Where a motion starts: the arm's configuration, or (dry runs only) a given one inside the limits."""
        if q_start is None:
            return self._current_q()
        return self.safety.check_joints(q_start).copy()

    def plan_pose(
        self, T_base_frame: np.ndarray, speed_scale: float = 1.0, free_roll: bool = False, frame: str = "gripper",
        q_start: np.ndarray | None = None,
    ) -> tuple[JointTrajectory, float]:
        """Joint-space motion to a pose (IK from the start configuration); returns (trajectory, roll)."""
        T = check_transform(T_base_frame, "target pose")
        q0 = self._start_q(q_start)
        sol = self.kinematics.ik(T, q0, frame=frame, free_roll=free_roll)
        self.safety.check_joints(sol.q)
        return plan_joint_motion(q0, sol.q, self.config.limits, speed_scale), sol.roll

    def plan_linear(
        self, T_base_frame: np.ndarray, speed_scale: float = 1.0, frame: str = "gripper",
        q_start: np.ndarray | None = None,
    ) -> JointTrajectory:
        T = check_transform(T_base_frame, "target pose")
        return plan_linear_motion(
            self.kinematics, self._start_q(q_start), T, self.config.limits, speed_scale, frame, self.config.line
        )

    def check(self, trajectory: JointTrajectory, allow_object_contact: bool = False,
              opening: float | None = None) -> dict:
        """Full pre-motion check (envelope + collisions); raises on the first violation."""
        n_env = self.safety.check_trajectory(trajectory)
        n_col = self.collision.check_trajectory(trajectory, self._opening if opening is None else opening,
                                                allow_object_contact)
        return {"envelope_samples": n_env, "collision_samples": n_col}

    # ------------------------------------------------------------------ moves
    def _run(self, trajectory: JointTrajectory, allow_object_contact: bool, dry_run: bool,
             opening: float | None = None) -> dict:
        info = {"duration_s": float(trajectory.duration), **self.check(trajectory, allow_object_contact, opening),
                "q_end": np.asarray(trajectory.q_end, dtype=np.float64).copy()}
        if dry_run:
            info["frames_end"] = self.kinematics.fk_frames(info["q_end"])  # still inside the motion lock
            return info
        if self._estopped:
            raise MotionStopped("emergency stop is latched; reset it before moving", code="estop_latched")
        self._fault = None
        self._moving = True
        try:
            result = execute(
                self.driver,
                trajectory,
                rate_hz=self.config.rate_hz,
                realtime=self.config.realtime,
                stop_event=self._stop,
                check=self.safety.check_setpoint,
                on_setpoint=self._on_setpoint,
            )
            if result.stopped:
                raise MotionStopped(
                    "motion halted by emergency stop",
                    detail={"after_s": round(result.elapsed_s, 3), "setpoints_sent": result.setpoints_sent},
                )
            # the last set-point is not the arm's position: every backend confirms the arm got there (a stop
            # ends that check at once)
            q = self.driver.settle(np.asarray(trajectory.q_end, dtype=np.float64), stop_event=self._stop)
            self._q = q
            if self._stop.is_set():
                raise MotionStopped("motion halted by emergency stop while settling",
                                    detail={"setpoints_sent": result.setpoints_sent})
        except (DriverError, EnvelopeError) as exc:
            self._hold_after_fault(exc)
            raise
        finally:
            self._moving = False
        info.update(setpoints_sent=result.setpoints_sent, elapsed_s=result.elapsed_s)
        return info

    def _on_setpoint(self, t: float, q: np.ndarray) -> None:
        self._q = q

    @contextmanager
    def _exclusive(self) -> Iterator[None]:
        """One motion at a time: a second request while moving is refused, not queued."""
        if not self._motion_lock.acquire(blocking=False):
            raise ArmError("another motion is running", code="busy")
        try:
            yield
        finally:
            self._motion_lock.release()

    def move_joints(self, q: np.ndarray, speed_scale: float = 1.0, dry_run: bool = False) -> dict:
        """Jerk-limited joint motion to ``q`` (6 rad). Returns timing and check figures."""
        with self._exclusive():
            return self._run(self.plan_joints(q, speed_scale), False, dry_run)

    def home(self, speed_scale: float = 1.0, dry_run: bool = False) -> dict:
        """Go to the backend's home posture (``driver.home_q``); a read-only backend (replay) rewinds instead."""
        if self.driver.read_only:
            with self._exclusive():
                self.driver.home()
                self._q = self.driver.read_joints()
            q = self._q.copy()
            return {"duration_s": 0.0, "setpoints_sent": 0, "q_end": q, "frames_end": self.kinematics.fk_frames(q)}
        return self.move_joints(self.driver.home_q, speed_scale, dry_run)

    def move_pose(
        self,
        T_base_gripper: np.ndarray,
        speed_scale: float = 1.0,
        free_roll: bool = False,
        frame: str = "gripper",
        allow_object_contact: bool = False,
        dry_run: bool = False,
        q_start: np.ndarray | None = None,
        check_opening: float | None = None,
    ) -> dict:
        """Joint-space motion putting ``frame`` (TCP by default) at a pose; ``roll`` in the reply when free.

        ``q_start`` (dry runs only) plans and checks the motion as if the arm stood there: a caller can check
        a whole chain of moves (pick, turn, place) before the first one runs. ``q_end`` in the reply is the
        configuration the motion ends in. ``check_opening`` (dry runs only): check with the fingers at that
        opening, e.g. closed on the object for a held move checked before the gripper closes.
        """
        self._dry_start(q_start, dry_run, check_opening)
        if frame == "gripper":
            self.safety.check_tcp(T_base_gripper)
        with self._exclusive():
            traj, roll = self.plan_pose(T_base_gripper, speed_scale, free_roll, frame, q_start)
            info = self._run(traj, allow_object_contact, dry_run, check_opening)
            info["roll"] = roll
            return info

    def move_linear(
        self,
        T_base_gripper: np.ndarray,
        speed_scale: float = 1.0,
        frame: str = "gripper",
        allow_object_contact: bool = False,
        dry_run: bool = False,
        q_start: np.ndarray | None = None,
        check_opening: float | None = None,
    ) -> dict:
        """Straight-line TCP motion (approach, lift, set down, retreat); ``q_start``, ``check_opening`` as in
        ``move_pose``."""
        self._dry_start(q_start, dry_run, check_opening)
        if frame == "gripper":
            self.safety.check_tcp(T_base_gripper)
        with self._exclusive():
            return self._run(self.plan_linear(T_base_gripper, speed_scale, frame, q_start), allow_object_contact,
                             dry_run, check_opening)

    @staticmethod
    def _dry_start(q_start: np.ndarray | None, dry_run: bool, check_opening: float | None = None) -> None:
        if q_start is not None and not dry_run:
            raise BadCommand("a start configuration is only allowed on a dry run", code="bad_value")
        if check_opening is not None and not dry_run:
            raise BadCommand("a check opening is only allowed on a dry run", code="bad_value")

    def gripper(self, opening: float, force: float | None = None) -> dict:
        """Drive the fingers to ``opening`` (m) with at most ``force`` (N); blocks until reached or stalled.

        ``grasped`` is True when the fingers stopped short of the target (closed on an object).
        """
        o, f = self.safety.check_gripper(opening, self.config.default_gripper_force if force is None else force)
        if self._estopped:
            raise MotionStopped("emergency stop is latched; reset it before moving", code="estop_latched")
        cfg = self.config
        with self._exclusive():
            self._gripper_busy = True
            try:
                return self._run_gripper(o, f, cfg)
            except (DriverError, EnvelopeError) as exc:
                self._hold_after_fault(exc)
                raise
            finally:
                self._gripper_busy = False

    def _run_gripper(self, o: float, f: float, cfg: ArmConfig) -> dict:
        # a new command: the grip policy of a stop is "hold where the fingers are" until they close on
        # something (then a stop keeps the grip: letting go of the object is no safer)
        self.driver.keep_grip = False
        self.driver.set_gripper(o, f)
        if self._stop.is_set():  # an e-stop came while the goal was on its way: hold again, after it
            self._hold_quietly()
            raise MotionStopped("gripper motion halted by emergency stop")
        t0 = last_change = time.monotonic()
        prev = self.driver.read_gripper()
        while True:
            cur = self.driver.read_gripper()
            self._opening = cur
            if abs(cur - o) <= cfg.gripper_tolerance:
                return {"opening": cur, "grasped": False, "elapsed_s": time.monotonic() - t0}
            now = time.monotonic()
            if abs(cur - prev) > 1e-4:
                last_change, prev = now, cur
            elif now - last_change > cfg.gripper_stall_s:
                self.driver.keep_grip = True
                return {"opening": cur, "grasped": True, "elapsed_s": now - t0}
            if now - t0 > cfg.gripper_timeout_s:
                raise DriverError(
                    "gripper did not reach its target in time",
                    code="gripper_timeout",
                    detail={"target": o, "opening": cur},
                )
            if self._stop.wait(0.01):
                raise MotionStopped("gripper motion halted by emergency stop")

    def _hold_quietly(self) -> None:
        try:
            self.driver.stop()
        except (DriverError, ArmError):
            pass  # the e-stop reports its own hold
