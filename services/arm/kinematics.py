"""PAPRAS kinematics on pinocchio: forward kinematics of any frame, Jacobians, and inverse kinematics.

The URDF is loaded once. The arm is a 6-DOF chain; the RH-P12-RN finger joints are locked out of the
*arm* model (they do not move the TCP or the camera) and live only in the *full* model, which the
collision checker uses with the finger angle that matches the commanded opening.

IK is damped least squares (Levenberg-Marquardt style) on a position + orientation error, clamped to
the joint limits at every step, restarted from several seeds (the caller's current configuration first,
then a few fixed postures, then seeded random ones). When it fails it says why: ``joint_limits`` (a
solution exists if the limits are ignored), ``singular`` (stuck where the Jacobian loses rank) or
``unreachable``. The ``free_roll`` variant drops the rotation about the gripper's approach axis (x) from
the task and, in the null space, pulls that roll towards zero, so it returns the reachable pose closest
to the requested one together with the roll it used.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from common.geometry import as_rigid_transform
from services.arm.errors import BadCommand, IKError
from services.arm.robot import JOINT_NAMES, MESH_PACKAGE_DIR, URDF_PATH

FINGER_JOINTS = ("robot1/gripper", "robot1/gripper_r2", "robot1/gripper_l1", "robot1/gripper_l2")
# mimic multipliers of the finger joints relative to robot1/gripper (from the URDF's <mimic> tags)
FINGER_MIMIC = (1.0, 1.0 / 1.1, 1.0, 1.0 / 1.1)
FRAME_ALIASES = {
    "base": "robot1/link1",
    "flange": "robot1/end_link",
    "gripper": "gripper",
    "camera": "camera",
}


@dataclass
class KinematicsConfig:
    """Where the robot comes from and how hard IK tries.

    ``T_gripper_camera`` is the hand-eye transform (camera optical frame in the TCP frame); ``None``
    keeps the URDF's mount. Tolerances are far below the 0.1 mm / 0.1 deg the pipeline needs so that
    round trips stay exact.
    """

    urdf_path: Path = URDF_PATH
    package_dir: Path = MESH_PACKAGE_DIR
    T_gripper_camera: np.ndarray | None = None
    ik_tol_position: float = 1e-6  # m
    ik_tol_rotation: float = 1e-5  # rad
    ik_max_iterations: int = 80  # per seed
    ik_damping: float = 1e-6
    ik_max_step: float = 0.4  # rad per iteration, keeps DLS from overshooting far from the target
    ik_num_seeds: int = 24  # including the caller's q and the fixed postures
    ik_max_solutions: int = 3  # converged solutions to compare before choosing the closest to q_init
    # the q_init seed's solution is taken at once only when no joint moves more than this (rad): DLS from a
    # far-away q_init can converge on another branch (measured: a 4.4 rad wrist swing chosen over 2.8 rad)
    ik_near_jump: float = 0.5
    ik_random_seed: int = 7
    roll_gain: float = 0.5  # null-space pull of the free roll towards 0 (free_roll only)
    fixed_seeds: tuple[tuple[float, ...], ...] = field(
        default_factory=lambda: (
            (0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            (0.0, 0.6, -1.2, 0.0, 0.6, 0.0),
            (0.0, -0.3, -1.0, 0.0, 1.2, 0.0),
            (0.0, 0.3, -1.8, 0.0, 1.4, 0.0),
        )
    )


@dataclass
class IKSolution:
    """A joint solution; ``roll`` is the angle (rad) about the gripper x-axis actually used (free roll)."""

    q: np.ndarray
    T_achieved: np.ndarray
    roll: float
    position_error: float
    rotation_error: float
    iterations: int
    seed_index: int


def _check_q(q: np.ndarray, n: int) -> np.ndarray:
    arr = np.asarray(q, dtype=np.float64)
    if arr.shape != (n,):
        raise BadCommand(
            f"joint vector must have shape ({n},)", code="bad_shape", detail={"shape": list(arr.shape)}
        )
    if not np.all(np.isfinite(arr)):
        raise BadCommand("joint vector contains NaN or inf", code="bad_value")
    return arr


def wrist_flip(q: np.ndarray) -> np.ndarray:
    """The other wrist solution of the same TCP pose: joint 4 and 6 turned by pi, joint 5 mirrored.

    PAPRAS's joints 4-5-6 are a roll-pitch-roll wrist, so Rz(a)Ry(b)Rz(c) = Rz(a+pi)Ry(-b)Rz(c+pi) gives the
    same flange pose (verified against FK in tests/arm/test_kinematics.py). Angles are wrapped to (-pi, pi].
    """
    out = np.asarray(q, dtype=np.float64).copy()
    out[3] += np.pi
    out[4] = -out[4]
    out[5] += np.pi
    out[[3, 5]] = (out[[3, 5]] + np.pi) % (2 * np.pi) - np.pi
    return out


def check_transform(T: np.ndarray, name: str = "pose") -> np.ndarray:
    """Validate a 4x4 rigid transform (shape, finiteness, orthonormal rotation); returns float64."""
    return as_rigid_transform(T, name, BadCommand)


class Kinematics:
    """FK, Jacobians and IK of the PAPRAS arm; one instance per process (the URDF is parsed once)."""

    def __init__(self, config: KinematicsConfig | None = None):
        self.config = config or KinematicsConfig()
        urdf = str(self.config.urdf_path)
        self.full_model: pin.Model = pin.buildModelFromUrdf(urdf)
        lock = [self.full_model.getJointId(n) for n in FINGER_JOINTS]
        self.model: pin.Model = pin.buildReducedModel(self.full_model, lock, pin.neutral(self.full_model))
        if [self.model.names[i] for i in range(1, self.model.njoints)] != list(JOINT_NAMES):
            raise RuntimeError(f"unexpected arm joints in {urdf}")
        self.data = self.model.createData()
        self.full_data = self.full_model.createData()
        self.nq = self.model.nq
        self.joint_names = list(JOINT_NAMES)
        self.lower = self.model.lowerPositionLimit.copy()
        self.upper = self.model.upperPositionLimit.copy()
        self.velocity_limit = self.model.velocityLimit.copy()
        self._frame_ids: dict[str, int] = {}
        if self.config.T_gripper_camera is not None:
            self.set_hand_eye(self.config.T_gripper_camera)
        self._rng = np.random.default_rng(self.config.ik_random_seed)
        self._random_seeds = self._make_random_seeds()
        self._opening_table = self._finger_table()

    # ------------------------------------------------------------------ frames
    def frame_id(self, frame: str) -> int:
        """pinocchio frame id of a frame name or alias (``base``, ``flange``, ``gripper``, ``camera``)."""
        fid = self._frame_ids.get(frame)
        if fid is None:
            name = FRAME_ALIASES.get(frame, frame)
            if not self.model.existFrame(name):
                raise BadCommand(
                    f"unknown frame {frame!r}", code="unknown_frame", detail={"known": sorted(FRAME_ALIASES)}
                )
            fid = self.model.getFrameId(name)
            self._frame_ids[frame] = fid
        return fid

    def set_hand_eye(self, T_gripper_camera: np.ndarray) -> None:
        """Replace the camera mount (camera optical frame in the TCP frame), e.g. after calibration."""
        T = check_transform(T_gripper_camera, "T_gripper_camera")
        gid, cid = self.frame_id("gripper"), self.frame_id("camera")
        g, c = self.model.frames[gid], self.model.frames[cid]
        if g.parentJoint != c.parentJoint:
            raise RuntimeError("gripper and camera frames must hang on the same joint")
        c.placement = g.placement * pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())
        self.model.frames[cid] = c

    @property
    def T_gripper_camera(self) -> np.ndarray:
        """The hand-eye transform in use."""
        g = self.model.frames[self.frame_id("gripper")].placement
        c = self.model.frames[self.frame_id("camera")].placement
        return (g.actInv(c)).homogeneous

    # ------------------------------------------------------------------ FK / Jacobians
    def fk(self, q: np.ndarray, frame: str = "gripper") -> np.ndarray:
        """T_base_frame (4x4) at joint configuration ``q``."""
        q = _check_q(q, self.nq)
        fid = self.frame_id(frame)
        pin.forwardKinematics(self.model, self.data, q)
        return pin.updateFramePlacement(self.model, self.data, fid).homogeneous

    def fk_frames(
        self, q: np.ndarray, frames: tuple[str, ...] = ("gripper", "camera")
    ) -> dict[str, np.ndarray]:
        """Several frames at once (one forward pass); cheap enough for a 50 Hz state stream."""
        q = _check_q(q, self.nq)
        pin.forwardKinematics(self.model, self.data, q)
        return {
            f: pin.updateFramePlacement(self.model, self.data, self.frame_id(f)).homogeneous for f in frames
        }

    def jacobian(
        self, q: np.ndarray, frame: str = "gripper", reference: str = "local_world_aligned"
    ) -> np.ndarray:
        """6 x nq frame Jacobian, linear rows first; reference local, world or local_world_aligned."""
        q = _check_q(q, self.nq)
        rf = {"local": pin.LOCAL, "world": pin.WORLD, "local_world_aligned": pin.LOCAL_WORLD_ALIGNED}.get(
            reference
        )
        if rf is None:
            raise BadCommand(f"unknown reference {reference!r}", code="bad_value")
        return pin.computeFrameJacobian(self.model, self.data, q, self.frame_id(frame), rf).copy()

    def within_limits(self, q: np.ndarray, tol: float = 1e-9) -> bool:
        return bool(np.all(q >= self.lower - tol) and np.all(q <= self.upper + tol))

    # ------------------------------------------------------------------ gripper fingers
    def _finger_table(self) -> tuple[np.ndarray, np.ndarray]:
        """Opening between the finger pads (m) against the finger joint angle, from the URDF linkage."""
        m, d = self.full_model, self.full_data
        gm = m.getFrameId("robot1/gripper_main_link")
        r2, l2 = m.getFrameId("robot1/gripper_link_r2"), m.getFrameId("robot1/gripper_link_l2")
        # inner face of the distal pads: y = -/+ 3.9 mm, 20 mm up the pad (rh_p12_rn_{r,l}2.stl)
        pad_r, pad_l = np.array([0.0, -0.0039, 0.02]), np.array([0.0, 0.0039, 0.02])
        angles = np.linspace(0.0, self.full_model.upperPositionLimit[6], 221)
        openings = []
        for g in angles:
            pin.framesForwardKinematics(m, d, self.full_q(np.zeros(6), finger_angle=g))
            pr = d.oMf[gm].actInv(d.oMf[r2]).act(pad_r)
            pl = d.oMf[gm].actInv(d.oMf[l2]).act(pad_l)
            openings.append(pr[1] - pl[1])
        return angles, np.maximum(np.asarray(openings), 0.0)

    @property
    def max_opening(self) -> float:
        return float(self._opening_table[1][0])

    def finger_angle(self, opening: float) -> float:
        """Finger joint angle (rad, URDF ``robot1/gripper``) that leaves ``opening`` m between the pads."""
        angles, openings = self._opening_table
        return float(np.interp(opening, openings[::-1], angles[::-1]))

    def opening(self, finger_angle: float) -> float:
        angles, openings = self._opening_table
        return float(np.interp(finger_angle, angles, openings))

    def full_q(
        self, q: np.ndarray, opening: float | None = None, finger_angle: float | None = None
    ) -> np.ndarray:
        """Configuration of the full model (arm + the four finger joints) for the collision checker."""
        g = (
            finger_angle
            if finger_angle is not None
            else (self.finger_angle(opening) if opening is not None else 0.0)
        )
        return np.concatenate([np.asarray(q, dtype=np.float64)[:6], [g * k for k in FINGER_MIMIC]])

    # ------------------------------------------------------------------ IK
    def _make_random_seeds(self) -> np.ndarray:
        n = max(self.config.ik_num_seeds - 1 - len(self.config.fixed_seeds), 0)
        lo = np.maximum(self.lower, -2.5)
        hi = np.minimum(self.upper, 2.5)
        return self._rng.uniform(lo, hi, size=(n, self.nq))

    def _seeds(self, q_init: np.ndarray | None) -> list[np.ndarray]:
        seeds = [] if q_init is None else [np.clip(q_init, self.lower, self.upper)]
        seeds += [np.asarray(s, dtype=np.float64) for s in self.config.fixed_seeds]
        seeds += list(self._random_seeds)
        return seeds

    def _solve(
        self, fid: int, R_des: np.ndarray, p_des: np.ndarray, q0: np.ndarray, free_roll: bool, clamp: bool
    ) -> tuple[np.ndarray, float, float, int, float]:
        """One DLS run; returns (q, position error, rotation error (task rows), iterations, roll)."""
        cfg, model, data = self.config, self.model, self.data
        lo, hi = self.lower, self.upper
        q = q0.copy()
        lam = cfg.ik_damping
        eye6 = np.eye(6)
        pe = re = np.inf
        roll = prev_roll = 0.0
        for it in range(cfg.ik_max_iterations):
            J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
            M = pin.updateFramePlacement(model, data, fid)
            R = M.rotation
            e_p = p_des - M.translation
            e_r = pin.log3(R.T @ R_des)  # rotation still to do, in the current TCP frame
            pe = float(np.sqrt(e_p @ e_p))
            roll = float(e_r[0])
            re = float(np.hypot(e_r[1], e_r[2])) if free_roll else float(np.sqrt(e_r @ e_r))
            if (
                pe < cfg.ik_tol_position
                and re < cfg.ik_tol_rotation
                and (not free_roll or abs(roll) < cfg.ik_tol_rotation or abs(roll - prev_roll) < 1e-7)
            ):
                return q, pe, re, it, roll
            prev_roll = roll
            Jr = R.T @ J[3:]  # angular rows in the TCP frame
            if free_roll:
                A = np.vstack([J[:3], Jr[1:]])
                e = np.concatenate([e_p, e_r[1:]])
                AAt = A @ A.T + (lam + 1e-3 * pe * pe) * np.eye(5)
                A_pinv = A.T @ np.linalg.inv(AAt)
                dq = A_pinv @ e
                # secondary task: bring the roll about x back towards 0 inside the (1-D) null space
                n_roll = (np.eye(self.nq) - A_pinv @ A) @ Jr[0]
                gain = Jr[0] @ n_roll
                if gain > 1e-6:
                    dq += n_roll * (cfg.roll_gain * e_r[0] - Jr[0] @ dq) / gain
            else:
                A = np.vstack([J[:3], Jr])
                e = np.concatenate([e_p, e_r])
                dq = A.T @ np.linalg.solve(A @ A.T + (lam + 1e-3 * pe * pe) * eye6, e)
            step = np.max(np.abs(dq))
            if step > cfg.ik_max_step:
                dq *= cfg.ik_max_step / step
            q = q + dq
            if clamp:
                np.clip(q, lo, hi, out=q)
        return q, pe, re, cfg.ik_max_iterations, roll

    def ik(
        self,
        T_target: np.ndarray,
        q_init: np.ndarray | None = None,
        frame: str = "gripper",
        free_roll: bool = False,
        local_only: bool = False,
    ) -> IKSolution:
        """Joint configuration putting ``frame`` at ``T_target`` (T_base_frame), within the joint limits.

        Seeds: ``q_init`` (the arm's current configuration, so small moves stay small) first. Among up
        to ``ik_max_solutions`` converged seeds, returns the one closest to ``q_init``. With
        ``free_roll=True`` the rotation about the frame's x-axis (the gripper's approach axis) is free;
        the solution's ``roll`` is the angle used: ``T_achieved = T_target @ Rx(roll)``.
        ``local_only=True`` solves from ``q_init`` alone (dense Cartesian paths: stay on one branch). The
        other wrist branch of every solution found is a candidate too.
        Raises ``IKError`` with code ``unreachable``, ``joint_limits`` or ``singular``.
        """
        T = check_transform(T_target, "T_target")
        if q_init is not None:
            q_init = _check_q(q_init, self.nq)
        fid = self.frame_id(frame)
        R_des, p_des = T[:3, :3].copy(), T[:3, 3].copy()
        ref = q_init if q_init is not None else np.zeros(self.nq)
        found: list[IKSolution] = []
        best_fail: tuple[float, np.ndarray] | None = None
        if local_only and q_init is None:
            raise BadCommand("local_only IK needs q_init", code="bad_value")
        seeds = [np.clip(q_init, self.lower, self.upper)] if local_only else self._seeds(q_init)
        for k, seed in enumerate(seeds):
            q, pe, re, its, roll = self._solve(fid, R_des, p_des, seed, free_roll, clamp=True)
            if self._converged(pe, re):
                found.append(self._solution(q, fid, roll if free_roll else 0.0, pe, re, its, k))
                if k == 0 and q_init is not None and float(np.max(np.abs(q - q_init))) <= self.config.ik_near_jump:
                    break  # the current configuration's branch: the least motion, no need to look further
                if len(found) >= self.config.ik_max_solutions:
                    break
            else:
                score = pe + 0.1 * re
                if best_fail is None or score < best_fail[0]:
                    best_fail = (score, q)
        if found and not local_only:
            found += self._wrist_flips(found, fid, R_des, p_des, free_roll)
        if found:
            return min(found, key=lambda s: float(np.sum((s.q - ref) ** 2)))
        if local_only:
            raise IKError(
                "no solution near q_init", code="unreachable", detail={"target_position": p_des.tolist()}
            )
        raise self._diagnose(fid, R_des, p_des, q_init, free_roll, best_fail)

    def _converged(self, pe: float, re: float) -> bool:
        return pe < self.config.ik_tol_position * 10 and re < self.config.ik_tol_rotation * 10

    def _wrist_flips(
        self, found: list[IKSolution], fid: int, R_des: np.ndarray, p_des: np.ndarray, free_roll: bool
    ) -> list[IKSolution]:
        """The other wrist branch of each solution found, when it lies inside the joint limits.

        The seeds rarely land on both wrist branches, and the one they miss is often the one closest to
        ``q_init`` (or the one with room to turn the wrist further). It is exact for PAPRAS's roll-pitch-roll
        wrist; a short polish keeps the tolerance honest should a hand-eye or URDF change break that.
        """
        out = []
        for sol in found:
            q = wrist_flip(sol.q)
            if not self.within_limits(q):
                continue
            if any(np.allclose(q, s.q, atol=1e-3) for s in found):
                continue
            q, pe, re, its, roll = self._solve(fid, R_des, p_des, q, free_roll, clamp=True)
            if self._converged(pe, re):
                out.append(self._solution(q, fid, roll if free_roll else 0.0, pe, re, its, sol.seed_index))
        return out

    def _solution(
        self, q: np.ndarray, fid: int, roll: float, pe: float, re: float, its: int, k: int
    ) -> IKSolution:
        pin.forwardKinematics(self.model, self.data, q)
        T = pin.updateFramePlacement(self.model, self.data, fid).homogeneous
        return IKSolution(
            q=q.copy(),
            T_achieved=T,
            roll=-roll,
            position_error=pe,
            rotation_error=re,
            iterations=its,
            seed_index=k,
        )

    def _diagnose(
        self,
        fid: int,
        R_des: np.ndarray,
        p_des: np.ndarray,
        q_init: np.ndarray | None,
        free_roll: bool,
        best_fail: tuple[float, np.ndarray] | None,
    ) -> IKError:
        """Why did IK fail? Try again without joint limits, then look at the Jacobian where it got stuck."""
        detail: dict = {"target_position": p_des.round(4).tolist(), "free_roll": free_roll}
        for seed in self._seeds(q_init)[:6]:
            q, pe, re, _, _ = self._solve(fid, R_des, p_des, seed, free_roll, clamp=False)
            if pe < self.config.ik_tol_position * 10 and re < self.config.ik_tol_rotation * 10:
                wrapped = (q + np.pi) % (2 * np.pi) - np.pi
                bad = [
                    self.joint_names[i]
                    for i in range(self.nq)
                    if not (self.lower[i] - 1e-9 <= wrapped[i] <= self.upper[i] + 1e-9)
                ]
                if bad:
                    detail["joints_out_of_limits"] = bad
                    return IKError(
                        "pose reachable only outside the joint limits", code="joint_limits", detail=detail
                    )
        if best_fail is not None:
            q = best_fail[1]
            J = pin.computeFrameJacobian(self.model, self.data, q, fid, pin.LOCAL_WORLD_ALIGNED)
            sv = np.linalg.svd(J, compute_uv=False)
            M = pin.updateFramePlacement(self.model, self.data, fid)
            residual = float(np.linalg.norm(p_des - M.translation))
            detail.update(residual_m=round(residual, 5), min_singular_value=float(sv[-1]))
            if sv[-1] < 1e-3 and residual < 0.01:
                return IKError("IK is stuck at a singular configuration", code="singular", detail=detail)
        return IKError("pose is out of the arm's reach", code="unreachable", detail=detail)
