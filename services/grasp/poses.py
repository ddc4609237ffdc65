"""Gripper orientations and the named pose set of a grasp (paper II-B.4 and II-B.5).

Gripper frame (docs/conventions.md, the paper's Fig. 4): x = approach, y = across the fingers, z = up
when approaching horizontally. The paper writes R = [n × y, p1 − p2, x × y]; taken literally with a
right-handed frame that makes z point down, so we fix y along the grasp line and choose x's sign from
where the arm comes from instead, which gives z up (see docs/grasp.md).

Per grasp, for every angular offset θ about the gripper's y (0, ±15°, and ±30°, ±45° for top-down):
    grasp_θ     the grasp rotated by θ about the grasp line itself (so the contacts stay put), TCP pushed
                ``depth`` past the contact midpoint along its own approach axis
    pregrasp_θ  the same, backed off ``back_off`` along its approach axis
    turn_θ      T_turn · grasp_θ with T_turn the turn about the table normal through the object centre,
                so whatever the hand holds turns about that vertical line
Names: ``grasp``, ``grasp_plus15``, ``grasp_minus15``, ..., ``pregrasp...``, ``turn...``.
"""

from __future__ import annotations

import numpy as np

from common.geometry import make_transform, rotation_about_line
from services.grasp.boxes import cross3


def frontal_rotation(p1: np.ndarray, p2: np.ndarray, up: np.ndarray, approach_origin: np.ndarray
                     ) -> tuple[np.ndarray, bool]:
    """Rotation of a horizontal-approach grasp on contacts p1, p2.

    y runs from p2 to p1 (the paper's p1 − p2); x = y × n is horizontal and perpendicular to the grasp
    line; when that points back toward ``approach_origin`` the contacts are swapped so the hand comes
    from the arm's side. Returns (R, swapped).
    """
    y = _unit(p1 - p2)
    x = cross3(y, up)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("grasp line parallel to the table normal has no horizontal approach")
    x = _unit(x)
    swapped = _points_back(x, p1, p2, up, approach_origin)
    if swapped:
        x, y = -x, -y
    return np.column_stack([x, y, cross3(x, y)]), swapped


def _points_back(axis: np.ndarray, p1: np.ndarray, p2: np.ndarray, up: np.ndarray,
                 approach_origin: np.ndarray) -> bool:
    """Whether ``axis`` points back toward ``approach_origin`` from the contacts' midpoint, in the table plane.

    Both grasp frames flip their sign on this: the hand must come from the arm's side of the object.
    """
    away = 0.5 * (p1 + p2) - np.asarray(approach_origin, float)
    away = away - (away @ up) * up
    return bool(np.linalg.norm(away) > 1e-9 and axis @ away < 0)


def top_down_rotation(p1: np.ndarray, p2: np.ndarray, up: np.ndarray, approach_origin: np.ndarray
                      ) -> tuple[np.ndarray, bool]:
    """Rotation of a downward-approach grasp: x = −n (made perpendicular to the grasp line), y along
    the grasp line, z = x × y horizontal and pointing away from ``approach_origin`` (the frontal frame
    pitched 90° about its y). Returns (R, swapped)."""
    y = _unit(p1 - p2)
    down = -(up - (up @ y) * y)
    if np.linalg.norm(down) < 1e-9:
        raise ValueError("grasp line parallel to the table normal has no downward approach")
    x = _unit(down)
    z = cross3(x, y)
    swapped = _points_back(z, p1, p2, up, approach_origin)
    if swapped:
        y, z = -y, -z
    return np.column_stack([x, y, z]), swapped


def offset_name(prefix: str, angle_deg: float) -> str:
    if angle_deg == 0:
        return prefix
    sign = "plus" if angle_deg > 0 else "minus"
    return f"{prefix}_{sign}{abs(angle_deg):g}"


def offset_angles(offsets_deg: tuple[float, ...]) -> list[float]:
    """0 first, then each offset as +θ, −θ: the order callers try them in (best first)."""
    out = [0.0]
    for a in offsets_deg:
        out += [float(a), -float(a)]
    return out


def grasp_poses(R: np.ndarray, midpoint: np.ndarray, depth: float, back_off: float,
                offsets_deg: tuple[float, ...], up: np.ndarray, center: np.ndarray, turn_deg: float
                ) -> dict[str, np.ndarray]:
    """Named 4x4 T_base_gripper poses: grasps, then pre-grasps, then turned grasps."""
    T_turn = rotation_about_line(up, center, np.radians(turn_deg))
    grasps, pres, turns = {}, {}, {}
    for angle in offset_angles(offsets_deg):
        R_off = R @ _rot_y(np.radians(angle))
        x = R_off[:, 0]
        T = make_transform(R_off, midpoint + depth * x)
        grasps[offset_name("grasp", angle)] = T
        pres[offset_name("pregrasp", angle)] = make_transform(R_off, T[:3, 3] - back_off * x)
        turns[offset_name("turn", angle)] = T_turn @ T
    return {**grasps, **pres, **turns}


def _rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if n < 1e-12:
        raise ValueError("zero-length vector")
    return v / n
