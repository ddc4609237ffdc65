"""Rigid-transform helpers shared by every service.

Conventions (see docs/conventions.md): SI units, right-handed frames, quaternions in ROS order
``(x, y, z, w)``, and ``T_a_b`` is a 4x4 float64 matrix that maps points expressed in frame ``b`` into
frame ``a`` (``p_a = T_a_b @ p_b``). Keeping these in one place is what lets the arm, the sim, the
registration and the grasp planner agree on what a pose means.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from common.errors import ObjscanError

# How far R @ R.T may be from the identity for a matrix to count as a rotation. Poses cross the wire as
# float64 and are composed from float64 parts, so real ones are orthonormal to ~1e-12; the bound only has
# to reject scaled, sheared or garbage matrices, and is loose enough to accept every pose any caller sent
# before the checks were one (they used 1e-4, 1e-5 and 1e-6).
RIGID_ATOL = 1e-4


def make_transform(rotation: np.ndarray | None = None, translation: np.ndarray | None = None) -> np.ndarray:
    """Build a 4x4 homogeneous transform from a 3x3 rotation and a 3-vector translation."""
    T = np.eye(4)
    if rotation is not None:
        T[:3, :3] = rotation
    if translation is not None:
        T[:3, 3] = np.asarray(translation, dtype=float).reshape(3)
    return T


def as_rigid_transform(T: Any, name: str, error: type[ObjscanError], *, class_code: bool = False,
                       atol: float = RIGID_ATOL) -> np.ndarray:
    """Return ``T`` as a float64 4x4 rigid transform, or raise ``error`` saying what is wrong.

    One check for every pose that enters a service (arm targets, camera poses, twin poses, calibration
    files, wire transforms, clouds' camera poses): a NaN, a scaled matrix or a reflection would otherwise
    silently corrupt what is computed from it. ``error`` is the caller's typed error; its code is
    ``bad_shape`` for a wrong shape and ``bad_value`` otherwise, or the error class's own code when
    ``class_code`` (a service whose callers branch on one code, e.g. the camera's ``bad_pose``).
    """

    def fail(message: str, code: str, **detail: Any) -> ObjscanError:
        return error(message, code=None if class_code else code, detail={"field": name, **detail})

    try:
        M = np.asarray(T, dtype=np.float64)
    except (TypeError, ValueError):
        raise fail(f"{name} is not a numeric array", "bad_value", type=type(T).__name__) from None
    if M.shape != (4, 4):
        raise fail(f"{name} must be 4x4, got {list(M.shape)}", "bad_shape", shape=list(M.shape))
    if not np.all(np.isfinite(M)):
        raise fail(f"{name} contains NaN or inf", "bad_value")
    R = M[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=atol) or np.linalg.det(R) < 0 or \
            not np.allclose(M[3], [0.0, 0.0, 0.0, 1.0]):
        raise fail(f"{name} is not a rigid transform (rotation not orthonormal, a reflection, or last row "
                   "not 0 0 0 1)", "bad_value")
    return M


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform, computed from R^T rather than a general matrix inverse."""
    R = T[:3, :3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out


def _apply(M: np.ndarray, t: np.ndarray | None, arr: np.ndarray) -> np.ndarray:
    """``arr @ M.T (+ t)`` in float64, written column by column.

    Why not the matmul: an (N, 3) x (3, 3) product goes to BLAS, which handles the thin shape badly and
    spins its threads: 90 ms CPU (470 ms wall on the shared box) for 300k points against 4 ms this way, and
    a static view transforms ~1M points, which dominated ``reconstruct``'s wall
    time. Same values to the last bit or one ulp.
    """
    p = arr.astype(np.float64, copy=False)
    out = np.empty(p.shape, dtype=np.float64)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    for i in range(3):
        col = x * M[i, 0]
        col += y * M[i, 1]
        col += z * M[i, 2]
        if t is not None:
            col += t[i]
        out[..., i] = col
    return out


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply ``T`` to an (N, 3) array (or one point); returns the dtype of ``points``."""
    pts = np.asarray(points)
    T = np.asarray(T, dtype=np.float64)
    return _apply(T[:3, :3], T[:3, 3], pts).astype(pts.dtype, copy=False)


def rotate_vectors(T: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Rotate direction vectors (normals) by the rotation part of ``T``."""
    vec = np.asarray(vectors)
    return _apply(np.asarray(T, dtype=np.float64)[:3, :3], None, vec).astype(vec.dtype, copy=False)


def quat_xyzw_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix from a quaternion in ROS order (x, y, z, w); the quaternion is normalised."""
    return Rotation.from_quat(np.asarray(q, dtype=float)).as_matrix()


def matrix_to_quat_xyzw(R: np.ndarray) -> np.ndarray:
    """Quaternion (x, y, z, w) with w >= 0, so equal rotations compare equal. A stack (N, 3, 3) gives (N, 4)
    in one call (tens of thousands of poses: a recording's joint states)."""
    q = Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat()
    return np.where(q[..., 3:4] < 0, -q, q)


def pose_to_matrix(position: np.ndarray, quat_xyzw: np.ndarray) -> np.ndarray:
    """4x4 transform from a position and an (x, y, z, w) quaternion."""
    return make_transform(quat_xyzw_to_matrix(quat_xyzw), position)


def matrix_to_pose(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position, quaternion xyzw) of a 4x4 transform."""
    return T[:3, 3].copy(), matrix_to_quat_xyzw(T[:3, :3])


def rotation_about_axis(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """3x3 rotation of ``angle_rad`` about a (not necessarily unit) axis."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    return Rotation.from_rotvec(axis * angle_rad).as_matrix()


def rotation_about_line(axis: np.ndarray, point: np.ndarray, angle_rad: float) -> np.ndarray:
    """4x4 transform rotating by ``angle_rad`` about the line through ``point`` along ``axis``.

    This is how a turn of the object on the table is expressed: about the table normal, through the
    object's centre.
    """
    R = rotation_about_axis(axis, angle_rad)
    p = np.asarray(point, dtype=float).reshape(3)
    return make_transform(R, p - R @ p)


def rotation_angle_deg(R: np.ndarray) -> float:
    """Angle of a rotation matrix in degrees (0..180), robust to rounding just outside [-1, 1]."""
    c = (np.trace(R[:3, :3]) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def transform_error(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """(translation error in metres, rotation error in degrees) between two transforms."""
    delta = invert(T_true) @ T_est
    return float(np.linalg.norm(delta[:3, 3])), rotation_angle_deg(delta[:3, :3])


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, 0.0, 1.0)) -> np.ndarray:
    """``T_world_camera`` of an optical-frame camera (z forward, x right, y down) at ``eye`` looking at ``target``.

    ``up`` is the world direction that should appear upward in the image.
    """
    eye = np.asarray(eye, dtype=float)
    z = np.asarray(target, dtype=float) - eye
    z /= np.linalg.norm(z)
    up = np.asarray(up, dtype=float)
    x = np.cross(z, up)  # image right; then y = z x x points down in the image (optical frame)
    if np.linalg.norm(x) < 1e-9:  # looking straight along `up`: pick any perpendicular
        x = np.cross(z, [1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return make_transform(np.column_stack([x, y, z]), eye)


def yaw_deg_about(axis: np.ndarray, R: np.ndarray) -> float:
    """Signed rotation angle of ``R`` about ``axis`` in degrees, for measuring an achieved turn."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    rotvec = Rotation.from_matrix(R[:3, :3]).as_rotvec()
    return float(np.degrees(np.dot(rotvec, axis)))
