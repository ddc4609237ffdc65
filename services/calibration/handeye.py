"""Hand-eye calibration as plain functions: AX = XB by OpenCV's solvers, compared, then refined on reprojection.

Each sample is one arm pose looking at a fixed ChArUco board: ``T_base_gripper`` (A, from the arm's
kinematics) and the board's pose in the camera (B, from PnP on the detected corners). The unknown is
``X = T_gripper_camera``, the camera's mount on the hand. OpenCV's closed-form solvers (Park, Tsai,
Daniilidis, ...) each give an X; they are compared by how well they agree with the data (the board's
pose in ``base`` should be the same from every view), the best one seeds a joint least-squares
refinement of X and the board pose on the corners' reprojection error, which is what the camera really
measured. No I/O here: the procedure (``procedure.py``) collects samples, tests call these directly.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from common.geometry import invert, make_transform, rotation_angle_deg, transform_error
from services.calibration.board import BoardError, CharucoSpec

#: OpenCV's AX = XB solvers compared by ``solve``.
METHODS = {"park": cv2.CALIB_HAND_EYE_PARK, "tsai": cv2.CALIB_HAND_EYE_TSAI,
           "daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS, "horaud": cv2.CALIB_HAND_EYE_HORAUD,
           "andreff": cv2.CALIB_HAND_EYE_ANDREFF}
MIN_SAMPLES = 3


@dataclass
class Sample:
    """One view: the hand's pose, the board's detected corners and their PnP pose in the camera."""

    T_base_gripper: np.ndarray
    T_camera_board: np.ndarray
    ids: np.ndarray
    pixels: np.ndarray


@dataclass
class MethodResult:
    """One solver's X and how consistent it is with the samples."""

    T_gripper_camera: np.ndarray
    board_spread_mm: float  # RMS distance of each view's board position (in base) from their mean
    board_spread_deg: float  # RMS angle of each view's board orientation from their mean
    reprojection_px: float  # RMS of the corners projected through X and the mean board pose


@dataclass
class HandEyeResult:
    """The refined X with its residuals, and every solver's answer for comparison."""

    T_gripper_camera: np.ndarray
    T_base_board: np.ndarray
    seed_method: str
    reprojection_px: float
    board_spread_mm: float
    board_spread_deg: float
    methods: dict[str, MethodResult] = field(default_factory=dict)
    samples: int = 0


def _check(samples: list[Sample]) -> None:
    if len(samples) < MIN_SAMPLES:
        raise BoardError(f"hand-eye calibration needs at least {MIN_SAMPLES} views with the board, got "
                         f"{len(samples)}", code="too_few_views", detail={"views": len(samples)})


def board_poses(samples: list[Sample], X: np.ndarray) -> np.ndarray:
    """(N, 4, 4) board pose in ``base`` seen from each view through mount X."""
    return np.stack([s.T_base_gripper @ X @ s.T_camera_board for s in samples])


def mean_pose(Ts: np.ndarray) -> np.ndarray:
    """Chordal mean of rigid transforms (rotation mean + mean translation)."""
    R = Rotation.from_matrix(Ts[:, :3, :3]).mean().as_matrix()
    return make_transform(R, Ts[:, :3, 3].mean(axis=0))


def reprojection_residuals(samples: list[Sample], X: np.ndarray, T_base_board: np.ndarray, K: np.ndarray,
                           spec: CharucoSpec) -> np.ndarray:
    """Pixel residuals (2 per corner, all views) of the board corners projected through X."""
    out = []
    for s in samples:
        T_cb = invert(s.T_base_gripper @ X) @ T_base_board
        p = spec.corners_board[s.ids] @ T_cb[:3, :3].T + T_cb[:3, 3]
        uv = p[:, :2] / p[:, 2:3] * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
        out.append((uv - s.pixels).ravel())
    return np.concatenate(out)


def _rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(r.reshape(-1, 2) ** 2) * 2))


def evaluate(samples: list[Sample], X: np.ndarray, K: np.ndarray, spec: CharucoSpec) -> MethodResult:
    """How well mount X explains the samples (see ``MethodResult``)."""
    Tb = board_poses(samples, X)
    mean = mean_pose(Tb)
    dt = np.linalg.norm(Tb[:, :3, 3] - mean[:3, 3], axis=1)
    dr = np.array([rotation_angle_deg(mean[:3, :3].T @ T[:3, :3]) for T in Tb])
    return MethodResult(X, float(np.sqrt(np.mean(dt ** 2)) * 1e3), float(np.sqrt(np.mean(dr ** 2))),
                        _rms(reprojection_residuals(samples, X, mean, K, spec)))


def solve(samples: list[Sample], K: np.ndarray, spec: CharucoSpec) -> dict[str, MethodResult]:
    """Every OpenCV AX = XB solver's X, evaluated; a solver that fails is left out."""
    _check(samples)
    Rg = [s.T_base_gripper[:3, :3] for s in samples]
    tg = [s.T_base_gripper[:3, 3] for s in samples]
    Rc = [s.T_camera_board[:3, :3] for s in samples]
    tc = [s.T_camera_board[:3, 3] for s in samples]
    out = {}
    for name, flag in METHODS.items():
        try:
            R, t = cv2.calibrateHandEye(Rg, tg, Rc, tc, method=flag)
        except cv2.error:  # a degenerate motion set for this solver: the others still answer
            continue
        X = make_transform(Rotation.from_matrix(R).as_matrix(), np.asarray(t).reshape(3))
        if np.all(np.isfinite(X)):
            out[name] = evaluate(samples, X, K, spec)
    if not out:
        raise BoardError("no hand-eye solver found a solution: the views lack rotation diversity",
                         code="degenerate_views", detail={"views": len(samples)})
    return out


def _unpack(p: np.ndarray) -> np.ndarray:
    return make_transform(Rotation.from_rotvec(p[:3]).as_matrix(), p[3:6])


def refine(samples: list[Sample], X0: np.ndarray, K: np.ndarray, spec: CharucoSpec) -> tuple[np.ndarray, np.ndarray]:
    """(X, T_base_board) minimising the corners' reprojection error over all views, from X0.

    Parameterised as small corrections on X0 and the mean board pose (rotation vector + translation), so
    the problem is well conditioned; a robust loss keeps one bad corner from pulling the answer.
    """
    B0 = mean_pose(board_poses(samples, X0))

    def residuals(p: np.ndarray) -> np.ndarray:
        return reprojection_residuals(samples, X0 @ _unpack(p[:6]), B0 @ _unpack(p[6:]), K, spec)

    sol = least_squares(residuals, np.zeros(12), loss="soft_l1", f_scale=1.0, x_scale=0.01, max_nfev=200)
    return X0 @ _unpack(sol.x[:6]), B0 @ _unpack(sol.x[6:])


def calibrate(samples: list[Sample], K: np.ndarray, spec: CharucoSpec) -> HandEyeResult:
    """Solve with every method, seed the refinement with the most consistent one, report residuals."""
    methods = solve(samples, K, spec)
    seed = min(methods, key=lambda m: methods[m].reprojection_px)
    X, B = refine(samples, methods[seed].T_gripper_camera, K, spec)
    final = evaluate(samples, X, K, spec)
    return HandEyeResult(T_gripper_camera=X, T_base_board=B, seed_method=seed,
                         reprojection_px=_rms(reprojection_residuals(samples, X, B, K, spec)),
                         board_spread_mm=final.board_spread_mm, board_spread_deg=final.board_spread_deg,
                         methods=methods, samples=len(samples))


def pose_difference(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """(mm, deg) between two mounts."""
    dt, dr = transform_error(T_est, T_true)
    return dt * 1e3, dr
