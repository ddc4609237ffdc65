"""Top-down grasps on a round section rolled toward the arm's base: a bottle or can lying across the line
from the base.

Why: a top-down grasp closes along a horizontal line; its offsets turn the hand about that line. On a bottle
lying across the base line the grasp line points at the base, so those offsets lean the hand sideways, and
at 0.60 m the wrist cannot point straight down (every pick was "unreachable", measured). But across a round
section every line through the section's centre is antipodal: the whole grasp, contacts and hand, may turn
about the lying axis and stays a grasp. Rolled that way the approach leans toward the base, the lean the arm
reaches. Added only where the cloud's section about that axis is round (a circle fit within ``tolerance``
over at least ``min_span_deg`` of arc), never on a box, whose corners would meet the pads.
"""

from __future__ import annotations

import numpy as np

from common.geometry import rotation_about_line


def round_section(xyz: np.ndarray, mid: np.ndarray, axis: np.ndarray, up: np.ndarray, slab: float = 0.012,
                  tolerance: float = 0.002, min_span_deg: float = 100.0, min_points: int = 30
                  ) -> tuple[np.ndarray, float] | None:
    """(centre, radius) of the object's section about the horizontal line along ``axis`` near ``mid``, when
    the points within ``slab`` of the section plane lie on a circle; None otherwise."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    u = np.asarray(up, float) - (np.asarray(up, float) @ a) * a
    if np.linalg.norm(u) < 1e-9:
        return None
    u = u / np.linalg.norm(u)
    v = np.cross(a, u)
    rel = np.asarray(xyz, float) - np.asarray(mid, float)
    sel = np.abs(rel @ a) <= slab
    if np.count_nonzero(sel) < min_points:
        return None
    x, y = rel[sel] @ v, rel[sel] @ u
    A = np.column_stack([2 * x, 2 * y, np.ones_like(x)])
    (cx, cy, c), *_ = np.linalg.lstsq(A, x**2 + y**2, rcond=None)
    r2 = c + cx**2 + cy**2
    if r2 <= 0:
        return None
    r = float(np.sqrt(r2))
    resid = np.abs(np.hypot(x - cx, y - cy) - r)
    angles = np.degrees(np.arctan2(y - cy, x - cx))
    if float(np.median(resid)) > tolerance or float(np.ptp(angles)) < min_span_deg:
        return None
    return np.asarray(mid, float) + cx * v + cy * u, r


def roll_poses(poses: dict[str, np.ndarray], R: np.ndarray, centre: np.ndarray, angles_deg: tuple[float, ...],
               up: np.ndarray, object_center: np.ndarray, turn_deg: float, approach_origin: np.ndarray
               ) -> dict[str, np.ndarray]:
    """The unrolled ``grasp``/``pregrasp`` of ``poses`` turned about the lying axis (the gripper's z through
    ``centre``) by each angle, both ways: ``grasp_rollminusA`` leans toward the arm's base, ``grasp_rollplusA``
    away; with their ``pregrasp_roll*`` and ``turn_roll*`` (the turn about the table normal through the object's
    centre)."""
    z = np.asarray(R, float)[:, 2]
    y = np.asarray(R, float)[:, 1]
    away = np.asarray(centre, float) - np.asarray(approach_origin, float)
    away = away - (away @ up) * up
    # R @ rot_z(phi) moves the approach x toward +y for phi > 0: toward the base when y points away from it
    toward = 1.0 if float(y @ away) > 0 else -1.0
    T_turn = rotation_about_line(up, object_center, np.radians(turn_deg))
    out: dict[str, np.ndarray] = {}
    for a in angles_deg:
        for name, sign in ((f"rollminus{a:g}", toward), (f"rollplus{a:g}", -toward)):
            T_roll = rotation_about_line(z, centre, np.radians(sign * a))
            g = T_roll @ poses["grasp"]
            out[f"grasp_{name}"] = g
            out[f"pregrasp_{name}"] = T_roll @ poses["pregrasp"]
            out[f"turn_{name}"] = T_turn @ g
    return out
