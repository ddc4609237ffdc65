"""Top-down grasps on a box pitched along their grasp line, away from the arm's base: the pick of a box thin
along the line from the base.

Why: a box wider than the gripper's stroke one way and thin the other way is held only across its thin side.
Standing thin along the line from the base, that grasp closes along the line from the base, and a top-down
hand closing that way can only lean sideways (its offsets turn it about the grasp line). Measured with the
arm's kinematics (every wrist yaw, TCP 0.15-0.25 m high): at 0.60 m from the base only approaches leaning at
least 40 degrees away from the base are reachable, at 0.45 m at least 20 degrees, and no sideways lean at all,
so every pick, turn, reposition and lay-down of such a box was unreachable and the run ended "limit: reach".

The hand may instead pitch about its own z (horizontal, across the grasp line) through the contacts' midpoint:
the approach then leans along the grasp line, away from the base, the lean the arm reaches. The pads close on the box's
faces at that angle; between parallel pads the box seats itself flat on them as they close and lift (MuJoCo
in the twin: a 6.6 x 10.9 x 23.8 cm box turned 39.7 degrees in the hand for a 40 degree pitch and was held),
so once lifted it is held exactly as the unpitched grasp would hold it, only tilted by the pitch. A pitched
grasp therefore has no ``turn`` pose of its own: it is the pick of a lay-down (``orchestrator/lay_down.py``),
whose hand poses after the pick are those of the unpitched ``grasp``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from common.geometry import rotation_about_line

#: A grasp line less than this cosine from the line from the base (horizontally) gets no pitched poses: the
#: pitch would lean the approach mostly sideways, which the arm does not reach either.
MIN_RADIAL_COS = 0.5


def pitch_name(angle_deg: float) -> str:
    """Suffix of a pitched pose: ``_pitch40`` (``grasp_pitch40``, ``pregrasp_pitch40``)."""
    return f"_pitch{angle_deg:g}"


def pitched(name: str) -> bool:
    """Whether pose ``name`` (``grasp...``) is a pitched one."""
    return "_pitch" in name


def pitch_poses(poses: dict[str, np.ndarray], R: np.ndarray, mid: np.ndarray, angles_deg: tuple[float, ...],
                up: np.ndarray, approach_origin: np.ndarray,
                pads_clear: Callable[[np.ndarray], bool] = lambda R: True) -> dict[str, np.ndarray]:
    """``grasp_pitchA`` and ``pregrasp_pitchA``: the unpitched ``grasp``/``pregrasp`` of ``poses`` (a top-down
    grasp with rotation ``R`` on contacts whose midpoint is ``mid``) turned by A degrees about the gripper's z
    through ``mid``, the approach leaning away from ``approach_origin``; only the angles whose open pads
    ``pads_clear`` finds clear of the object (tilted against its faces, open pads reach into a thick box:
    the faces cross the 4 cm pad at the pitch, so a 40 degree pitch needs 8.6 + 3.4 cm of opening across a
    6.6 cm box, more than the 10.6 cm stroke). Empty when the grasp line runs across the line from the base."""
    y = np.asarray(R, float)[:, 1]
    z = np.asarray(R, float)[:, 2]
    up = np.asarray(up, float)
    mid = np.asarray(mid, float)
    away = mid - np.asarray(approach_origin, float)
    away = away - (away @ up) * up
    y_flat = y - (y @ up) * up
    if np.linalg.norm(away) < 1e-9 or np.linalg.norm(y_flat) < 1e-9:
        return {}
    cos = float(y_flat @ away) / float(np.linalg.norm(y_flat) * np.linalg.norm(away))
    if abs(cos) < MIN_RADIAL_COS:
        return {}
    # a turn by +phi about z moves the approach x toward +y: away from the base when y points away from it
    sign = 1.0 if cos > 0 else -1.0
    out: dict[str, np.ndarray] = {}
    for a in angles_deg:
        T = rotation_about_line(z, mid, np.radians(sign * float(a)))
        if not pads_clear(T[:3, :3] @ R):
            continue
        suffix = pitch_name(a)
        out["grasp" + suffix] = T @ poses["grasp"]
        out["pregrasp" + suffix] = T @ poses["pregrasp"]
    return out
