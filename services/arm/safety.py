"""The safety envelope: what the arm refuses to do, whoever asks.

Every command is checked *before* anything moves, so an out-of-envelope command is never partly executed:
the whole trajectory is sampled and each sample must keep the joints inside their (shrunk) limits, the
joint velocities and accelerations under their caps, and the TCP inside the workspace box and above the
table by a minimum height. Gripper commands are checked for opening range and force. While a motion
streams, ``check_setpoint`` re-checks each set-point (limits and step size) as a last line of defence.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from services.arm.errors import BadCommand, EnvelopeError
from services.arm.kinematics import Kinematics, check_transform
from services.arm.motion import NDOF, JointTrajectory, MotionLimits
from services.arm.workspace import WORKSPACE_MAX, WORKSPACE_MIN


@dataclass
class SafetyConfig:
    """Hard limits. Planning limits (``MotionLimits``) must sit inside these caps.

    The workspace box bounds the TCP in ``base``; ``min_tcp_height`` keeps it above the table top
    (z = 0). The force limit protects objects and the RH-P12-RN (170 N max per its e-manual).
    """

    joint_margin: float = 0.01  # rad kept free inside each URDF joint limit
    max_velocity: np.ndarray = field(default_factory=lambda: np.full(NDOF, 1.5))
    max_acceleration: np.ndarray = field(default_factory=lambda: np.full(NDOF, 4.0))
    workspace_min: tuple[float, float, float] = WORKSPACE_MIN
    workspace_max: tuple[float, float, float] = WORKSPACE_MAX
    min_tcp_height: float = 0.01
    max_gripper_force: float = 80.0  # N
    max_gripper_opening: float = 0.106  # m, RH-P12-RN stroke (rev 1)
    check_rate_hz: float = 100.0
    tolerance: float = 1e-6  # relative slack for sampled limit checks (float round-off)

    def __post_init__(self) -> None:
        self.max_velocity = np.broadcast_to(np.asarray(self.max_velocity, dtype=float), (NDOF,)).copy()
        self.max_acceleration = np.broadcast_to(np.asarray(self.max_acceleration, dtype=float), (NDOF,)).copy()


class SafetyEnvelope:
    """Checks joint targets, poses, trajectories, streamed set-points and gripper commands."""

    def __init__(self, kinematics: Kinematics, config: SafetyConfig | None = None):
        self.kin = kinematics
        self.config = config or SafetyConfig()
        m = self.config.joint_margin
        self.lower = kinematics.lower + m
        self.upper = kinematics.upper - m

    def check_limits_fit(self, limits: MotionLimits) -> None:
        """Planning limits must not exceed the envelope's caps."""
        cfg = self.config
        if np.any(limits.max_velocity > cfg.max_velocity * (1 + cfg.tolerance)) or np.any(
            limits.max_acceleration > cfg.max_acceleration * (1 + cfg.tolerance)
        ):
            raise EnvelopeError(
                "motion limits exceed the safety caps",
                code="limits_too_high",
                detail={"max_velocity": cfg.max_velocity.tolist(), "max_acceleration": cfg.max_acceleration.tolist()},
            )

    def check_joints(self, q: np.ndarray) -> np.ndarray:
        """A finite 6-vector inside the (shrunk) joint limits; returns it as float64."""
        arr = np.asarray(q, dtype=np.float64)
        if arr.shape != (NDOF,):
            raise BadCommand("joint target must have 6 values", code="bad_shape", detail={"shape": list(arr.shape)})
        if not np.all(np.isfinite(arr)):
            raise BadCommand("joint target contains NaN or inf", code="bad_value")
        bad = np.flatnonzero((arr < self.lower - 1e-9) | (arr > self.upper + 1e-9))
        if bad.size:
            i = int(bad[0])
            raise EnvelopeError(
                f"{self.kin.joint_names[i]} = {arr[i]:.4f} rad is outside [{self.lower[i]:.4f}, {self.upper[i]:.4f}]",
                code="joint_limit",
                detail={
                    "joint": self.kin.joint_names[i],
                    "value": float(arr[i]),
                    "lower": float(self.lower[i]),
                    "upper": float(self.upper[i]),
                },
            )
        return arr

    def check_tcp(self, T_base_gripper: np.ndarray) -> None:
        """TCP inside the workspace box and above the table by ``min_tcp_height``."""
        T = check_transform(T_base_gripper, "T_base_gripper")
        p = T[:3, 3]
        cfg = self.config
        if p[2] < cfg.min_tcp_height:
            raise EnvelopeError(
                f"TCP height {p[2]:.4f} m is below the minimum {cfg.min_tcp_height} m above the table",
                code="tcp_height",
                detail={"z": float(p[2]), "min": cfg.min_tcp_height},
            )
        lo, hi = np.asarray(cfg.workspace_min), np.asarray(cfg.workspace_max)
        if np.any(p < lo) or np.any(p > hi):
            raise EnvelopeError(
                "TCP leaves the workspace box",
                code="workspace",
                detail={"position": p.round(4).tolist(), "min": lo.tolist(), "max": hi.tolist()},
            )

    def check_trajectory(self, trajectory: JointTrajectory) -> int:
        """Every sample inside joints/velocity/acceleration limits, TCP in the box; returns samples checked."""
        cfg = self.config
        s = trajectory.sample(cfg.check_rate_hz)
        tol = 1 + cfg.tolerance
        for q in (s.q[0], s.q[-1]):
            self.check_joints(q)
        lo_bad = np.argwhere(s.q < self.lower - 1e-9)
        hi_bad = np.argwhere(s.q > self.upper + 1e-9)
        if lo_bad.size or hi_bad.size:
            k, i = (lo_bad if lo_bad.size else hi_bad)[0]
            self.check_joints(s.q[k])  # raises with the joint named
        for name, arr, cap, code in (
            ("velocity", s.qd, cfg.max_velocity, "velocity_limit"),
            ("acceleration", s.qdd, cfg.max_acceleration, "acceleration_limit"),
        ):
            ratio = np.abs(arr) / cap
            if np.max(ratio) > tol:
                k, i = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
                raise EnvelopeError(
                    f"{self.kin.joint_names[i]} {name} {abs(arr[k, i]):.3f} exceeds {cap[i]:.3f}",
                    code=code,
                    detail={
                        "joint": self.kin.joint_names[i],
                        "value": float(abs(arr[k, i])),
                        "limit": float(cap[i]),
                        "t": float(s.t[k]),
                    },
                )
        for q in s.q:
            self.check_tcp(self.kin.fk(q, "gripper"))
        return len(s)

    def check_setpoint(self, q: np.ndarray, q_prev: np.ndarray | None, dt: float) -> np.ndarray:
        """Last line of defence while streaming: limits, and a step no faster than the velocity cap."""
        arr = self.check_joints(q)
        if q_prev is not None and dt > 0:
            step = np.abs(arr - q_prev)
            cap = self.config.max_velocity * dt * 1.5 + 1e-6
            if np.any(step > cap):
                i = int(np.argmax(step / cap))
                raise EnvelopeError(
                    f"set-point jumps {step[i]:.4f} rad on {self.kin.joint_names[i]} in {dt:.4f} s",
                    code="velocity_limit",
                    detail={"joint": self.kin.joint_names[i], "step": float(step[i]), "dt": dt},
                )
        return arr

    def check_gripper(self, opening: float, force: float) -> tuple[float, float]:
        """Opening within [0, max] m and force within [0, max] N; returns them as floats."""
        cfg = self.config
        try:
            o, f = float(opening), float(force)
        except (TypeError, ValueError):
            raise BadCommand("gripper opening and force must be numbers", code="bad_value") from None
        if not (np.isfinite(o) and np.isfinite(f)):
            raise BadCommand("gripper opening and force must be finite", code="bad_value")
        if not 0.0 <= o <= cfg.max_gripper_opening + 1e-9:
            raise EnvelopeError(
                f"gripper opening {o:.4f} m is outside [0, {cfg.max_gripper_opening}]",
                code="gripper_opening",
                detail={"opening": o, "max": cfg.max_gripper_opening},
            )
        if not 0.0 <= f <= cfg.max_gripper_force:
            raise EnvelopeError(
                f"gripper force {f:.1f} N is outside [0, {cfg.max_gripper_force}] N",
                code="gripper_force",
                detail={"force": f, "max": cfg.max_gripper_force},
            )
        return o, f
