"""Jerk-limited, time-optimal joint trajectories (Ruckig) and straight Cartesian segments.

Two kinds of trajectory share one interface (``duration``, ``at(t)``, ``sample(rate_hz)``):

- ``RuckigTrajectory``: point-to-point in joint space, all joints synchronised, within per-joint
  velocity, acceleration and jerk limits (Ruckig's offline ``Trajectory``).
- ``PathTrajectory``: a dense joint path q(u), u in [0, 1] (from IK along a Cartesian line), timed by a
  1-DOF Ruckig profile u(t). Ruckig's intermediate waypoints are *not* used: the community edition sends
  those to a cloud service. The 1-DOF limits come from the path derivatives (dq/du, d2q/du2, d3q/du3),
  and the result is then checked on a dense time grid and, if any joint would exceed a limit, re-planned
  once with the time-scaled limits (a time-optimal profile with limits (v/c, a/c^2, j/c^3) is the same
  profile slowed by c, so one re-plan makes every joint satisfy its limits).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from ruckig import InputParameter, Result, Ruckig, Trajectory
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, Slerp

from services.arm.errors import BadCommand, IKError, TrajectoryError
from services.arm.kinematics import Kinematics, check_transform

NDOF = 6


@dataclass
class MotionLimits:
    """Per-joint limits used for planning (rad/s, rad/s^2, rad/s^3).

    Defaults are deliberately gentle for scanning with a camera on the wrist, well inside the URDF's
    3.04 rad/s.
    """

    max_velocity: np.ndarray = field(default_factory=lambda: np.full(NDOF, 1.0))
    max_acceleration: np.ndarray = field(default_factory=lambda: np.full(NDOF, 2.0))
    max_jerk: np.ndarray = field(default_factory=lambda: np.full(NDOF, 15.0))

    def __post_init__(self) -> None:
        for name in ("max_velocity", "max_acceleration", "max_jerk"):
            v = np.broadcast_to(np.asarray(getattr(self, name), dtype=np.float64), (NDOF,)).copy()
            if not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise BadCommand(
                    f"{name} must be positive and finite", code="bad_value", detail={name: v.tolist()}
                )
            setattr(self, name, v)

    def capped(self, max_velocity: np.ndarray | None, max_acceleration: np.ndarray | None) -> MotionLimits:
        """These limits, lowered per joint to what the hardware allows (e.g. servo profile caps)."""
        v = self.max_velocity if max_velocity is None else np.minimum(self.max_velocity, max_velocity)
        a = self.max_acceleration if max_acceleration is None else np.minimum(self.max_acceleration, max_acceleration)
        return MotionLimits(v, a, self.max_jerk.copy())

    def scaled(self, speed_scale: float) -> MotionLimits:
        """Limits of the same motion slowed down in time by 1/speed_scale (v*s, a*s^2, j*s^3)."""
        s = float(speed_scale)
        if not np.isfinite(s) or not 0.0 < s <= 1.0:
            raise BadCommand("speed_scale must be in (0, 1]", code="bad_value", detail={"speed_scale": s})
        return MotionLimits(self.max_velocity * s, self.max_acceleration * s * s, self.max_jerk * s**3)


@dataclass
class TrajectorySamples:
    """A trajectory sampled at a fixed rate: times (N,), positions, velocities, accelerations (N, 6)."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])


class JointTrajectory:
    """Interface: a joint motion that can be evaluated at any time in [0, duration]."""

    duration: float

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        raise NotImplementedError

    @property
    def q_start(self) -> np.ndarray:
        return self.at(0.0)[0]

    @property
    def q_end(self) -> np.ndarray:
        return self.at(self.duration)[0]

    def sample(self, rate_hz: float) -> TrajectorySamples:
        """Samples every 1/rate_hz s, always including both ends."""
        if not np.isfinite(rate_hz) or rate_hz <= 0:
            raise BadCommand("rate_hz must be positive", code="bad_value")
        n = max(int(np.ceil(self.duration * rate_hz)), 1)
        ts = np.minimum(np.arange(n + 1) / rate_hz, self.duration)
        out = [self.at(float(t)) for t in ts]
        return TrajectorySamples(
            ts, np.array([o[0] for o in out]), np.array([o[1] for o in out]), np.array([o[2] for o in out])
        )


class RuckigTrajectory(JointTrajectory):
    """Point-to-point joint trajectory from rest to rest, synchronised over all joints."""

    def __init__(self, trajectory: Trajectory, q_start: np.ndarray, q_goal: np.ndarray):
        self._traj = trajectory
        self.duration = float(trajectory.duration)
        self._q0, self._q1 = q_start, q_goal

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if t >= self.duration:
            return self._q1.copy(), np.zeros(NDOF), np.zeros(NDOF)
        p, v, a = self._traj.at_time(max(t, 0.0))
        return np.asarray(p), np.asarray(v), np.asarray(a)


class PathTrajectory(JointTrajectory):
    """A geometric joint path q(u) (cubic spline through dense IK points) timed by a 1-DOF Ruckig u(t)."""

    def __init__(self, path: CubicSpline, timing: Trajectory, q_points: np.ndarray):
        self._path = path
        self._d1, self._d2 = path.derivative(1), path.derivative(2)
        self._timing = timing
        self.duration = float(timing.duration)
        self.q_points = q_points

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if t >= self.duration:
            return self.q_points[-1].copy(), np.zeros(NDOF), np.zeros(NDOF)
        (u,), (ud,), (udd,) = self._timing.at_time(max(t, 0.0))
        u = min(max(u, 0.0), 1.0)
        q1 = self._d1(u)
        return self._path(u), q1 * ud, self._d2(u) * ud * ud + q1 * udd

    def sample(self, rate_hz: float) -> TrajectorySamples:
        """Vectorised: one Ruckig call per sample for u(t), then the spline on all samples at once."""
        if not np.isfinite(rate_hz) or rate_hz <= 0:
            raise BadCommand("rate_hz must be positive", code="bad_value")
        n = max(int(np.ceil(self.duration * rate_hz)), 1)
        ts = np.minimum(np.arange(n + 1) / rate_hz, self.duration)
        uu = np.array([[x[0] for x in self._timing.at_time(float(t))] for t in ts])
        u, ud, udd = np.clip(uu[:, 0], 0.0, 1.0), uu[:, 1:2], uu[:, 2:3]
        ud[-1] = udd[-1] = 0.0
        q1 = self._d1(u)
        q = self._path(u)
        q[-1] = self.q_points[-1]
        return TrajectorySamples(ts, q, q1 * ud, self._d2(u) * ud * ud + q1 * udd)


def _check_q(q: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(q, dtype=np.float64)
    if arr.shape != (NDOF,) or not np.all(np.isfinite(arr)):
        raise BadCommand(
            f"{name} must be 6 finite joint values", code="bad_value", detail={"shape": list(arr.shape)}
        )
    return arr


def _ruckig_offline(dofs: int, q0, q1, v, a, j) -> Trajectory:
    otg = Ruckig(dofs)
    inp = InputParameter(dofs)
    inp.current_position = list(q0)
    inp.target_position = list(q1)
    inp.current_velocity = inp.current_acceleration = [0.0] * dofs
    inp.target_velocity = inp.target_acceleration = [0.0] * dofs
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = list(v), list(a), list(j)
    traj = Trajectory(dofs)
    res = otg.calculate(inp, traj)
    if res not in (Result.Working, Result.Finished):
        raise TrajectoryError(
            f"Ruckig could not compute the trajectory ({res.name})", detail={"result": res.name}
        )
    return traj


def plan_joint_motion(
    q_start: np.ndarray, q_goal: np.ndarray, limits: MotionLimits | None = None, speed_scale: float = 1.0
) -> RuckigTrajectory:
    """Time-optimal, jerk-limited joint motion from rest at ``q_start`` to rest at ``q_goal``."""
    q0, q1 = _check_q(q_start, "q_start"), _check_q(q_goal, "q_goal")
    lim = (limits or MotionLimits()).scaled(speed_scale)
    traj = _ruckig_offline(NDOF, q0, q1, lim.max_velocity, lim.max_acceleration, lim.max_jerk)
    return RuckigTrajectory(traj, q0, q1)


def _path_derivative_bounds(path: CubicSpline, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    u = np.linspace(0.0, 1.0, n)
    return (
        np.max(np.abs(path(u, 1)), axis=0),
        np.max(np.abs(path(u, 2)), axis=0),
        np.max(np.abs(path(u, 3)), axis=0),
    )


def _peak_ratios(
    traj: JointTrajectory, lim: MotionLimits, rate_hz: float = 250.0
) -> tuple[float, float, float]:
    """Largest |qd|/v, |qdd|/a, |jerk|/j over a dense time grid (jerk by finite differences of qdd)."""
    s = traj.sample(rate_hz)
    rv = float(np.max(np.abs(s.qd) / lim.max_velocity))
    ra = float(np.max(np.abs(s.qdd) / lim.max_acceleration))
    rj = 0.0
    if len(s) > 2:
        jerk = np.diff(s.qdd, axis=0) / np.diff(s.t)[:, None].clip(min=1e-9)
        rj = float(np.max(np.abs(jerk) / lim.max_jerk))
    return rv, ra, rj


def plan_path_motion(
    q_points: np.ndarray, limits: MotionLimits | None = None, speed_scale: float = 1.0
) -> PathTrajectory:
    """Time a dense joint path (N x 6, N >= 2, evenly spaced along the task) from rest to rest."""
    Q = np.asarray(q_points, dtype=np.float64)
    if Q.ndim != 2 or Q.shape[1] != NDOF or Q.shape[0] < 2 or not np.all(np.isfinite(Q)):
        raise BadCommand(
            "q_points must be an (N>=2, 6) finite array", code="bad_shape", detail={"shape": list(Q.shape)}
        )
    lim = (limits or MotionLimits()).scaled(speed_scale)
    u = np.linspace(0.0, 1.0, Q.shape[0])
    path = CubicSpline(u, Q, axis=0, bc_type="natural" if Q.shape[0] > 2 else "not-a-knot")
    d1, d2, d3 = _path_derivative_bounds(path, max(10 * Q.shape[0], 200))
    if np.max(d1) < 1e-12:  # no motion
        return PathTrajectory(path, _ruckig_offline(1, [0.0], [0.0], [1.0], [1.0], [1.0]), Q)
    eps = 1e-12
    # split each joint limit between the terms of q' = q_u u', q'' = q_uu u'^2 + q_u u'',
    # q''' = q_uuu u'^3 + 3 q_uu u' u'' + q_u u''' (half / half, thirds)
    v = min(
        np.min(lim.max_velocity / (d1 + eps)),
        np.min(np.sqrt(0.5 * lim.max_acceleration / (d2 + eps))),
        np.min(np.cbrt(lim.max_jerk / 3.0 / (d3 + eps))),
    )
    a = np.min(0.5 * lim.max_acceleration / (d1 + eps))
    a = min(a, np.min(lim.max_jerk / 3.0 / (3.0 * d2 * v + eps)))
    j = np.min(lim.max_jerk / 3.0 / (d1 + eps))
    timing = _ruckig_offline(1, [0.0], [1.0], [v], [a], [j])
    traj = PathTrajectory(path, timing, Q)
    rv, ra, rj = _peak_ratios(traj, lim)
    # re-plan once, time-scaled so that the binding joint limit is met with 1 % to spare
    c = 1.01 * max(rv, np.sqrt(ra), np.cbrt(rj))
    timing = _ruckig_offline(1, [0.0], [1.0], [v / c], [a / c**2], [j / c**3])
    return PathTrajectory(path, timing, Q)


@dataclass
class LinePathConfig:
    """Spacing of the dense IK along a Cartesian line and the continuity test."""

    step_m: float = 0.004
    step_rad: float = np.radians(2.0)
    max_joint_step: float = 0.12  # rad between neighbouring IK points; more means a branch flip ...
    # ... unless halving the step (up to this many times) brings every step under it: near a wrist
    # singularity the joints move fast but continuously (a flip does not shrink when the step does)
    max_refinements: int = 3


def cartesian_line_path(
    kin: Kinematics,
    q_start: np.ndarray,
    T_goal: np.ndarray,
    frame: str = "gripper",
    config: LinePathConfig | None = None,
) -> np.ndarray:
    """Dense joint path (N x 6) moving ``frame`` on a straight line (slerp in orientation) to ``T_goal``.

    Each point is solved from the previous one only, so the arm stays on one IK branch. A step whose joints
    move more than ``max_joint_step`` is halved (up to ``max_refinements`` times); a jump that survives
    that is a branch flip and raises ``TrajectoryError`` (with the fraction of the line done), as does a
    point without a solution.
    """
    cfg = config or LinePathConfig()
    q0 = _check_q(q_start, "q_start")
    T1 = check_transform(T_goal, "T_goal")
    T0 = kin.fk(q0, frame)
    dist = float(np.linalg.norm(T1[:3, 3] - T0[:3, 3]))
    rots = Rotation.from_matrix(np.stack([T0[:3, :3], T1[:3, :3]]))
    ang = float((rots[0].inv() * rots[1]).magnitude())
    n = max(int(np.ceil(dist / cfg.step_m)), int(np.ceil(ang / cfg.step_rad)), 1)
    slerp = Slerp([0.0, 1.0], rots)

    def pose(s: float) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = slerp(s).as_matrix()
        T[:3, 3] = T0[:3, 3] + s * (T1[:3, 3] - T0[:3, 3])
        return T

    def solve(s: float, q_prev: np.ndarray) -> np.ndarray:
        try:
            return kin.ik(pose(s), q_prev, frame=frame, local_only=True).q
        except IKError as e:
            raise TrajectoryError(
                "straight line leaves the reachable workspace",
                code="line_unreachable",
                detail={"fraction": round(float(s), 3), "reason": e.code},
            ) from e

    def step(sa: float, qa: np.ndarray, sb: float, depth: int) -> list[np.ndarray]:
        qb = solve(sb, qa)
        jump = float(np.max(np.abs(qb - qa)))
        if jump <= cfg.max_joint_step:
            return [qb]
        if depth >= cfg.max_refinements:
            raise TrajectoryError(
                "straight line needs a joint jump (near a singularity or a branch flip)",
                code="line_discontinuous",
                detail={"fraction": round(float(sb), 3), "jump_rad": round(jump, 4)},
            )
        mid = 0.5 * (sa + sb)
        left = step(sa, qa, mid, depth + 1)
        return left + step(mid, left[-1], sb, depth + 1)

    s = np.linspace(0.0, 1.0, n + 1)
    points = [q0]
    for i in range(1, n + 1):
        points += step(float(s[i - 1]), points[-1], float(s[i]), 0)
    return np.array(points)


def plan_linear_motion(
    kin: Kinematics,
    q_start: np.ndarray,
    T_goal: np.ndarray,
    limits: MotionLimits | None = None,
    speed_scale: float = 1.0,
    frame: str = "gripper",
    config: LinePathConfig | None = None,
) -> PathTrajectory:
    """Straight-line Cartesian motion (approach, lift, set down, retreat) with jerk-limited timing."""
    Q = cartesian_line_path(kin, q_start, T_goal, frame=frame, config=config)
    return plan_path_motion(Q, limits, speed_scale)
