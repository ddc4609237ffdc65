"""Where the camera looks from during a hand-eye calibration: pure geometry, no robot.

AX = XB is only well posed when the hand turns about several non-parallel axes between views (Tsai's
condition); translations alone leave the mount's rotation unobservable. So the views spread over
azimuth, elevation and distance around the board and add a roll about the optical axis, all on the
arm's side of the board where PAPRAS reaches, each still seeing the whole board.
"""

from __future__ import annotations

import numpy as np

from common.geometry import make_transform, rotation_about_axis
from services.orchestrator.planning import arm_side_azimuth_deg, camera_pose_looking_at


def calibration_views(board_center: np.ndarray, n: int = 15, seed: int = 0, *,
                      distances: tuple[float, float] = (0.30, 0.38), elevations_deg: tuple[float, float] = (38.0, 62.0),
                      azimuth_span_deg: float = 40.0, roll_deg: float = 25.0) -> list[np.ndarray]:
    """``n`` camera poses (T_base_camera) looking at ``board_center``; deterministic for a seed.

    Views are laid on a golden-angle spiral over the azimuth/elevation window (even coverage for any n)
    with distance and roll drawn per view, so consecutive views differ in rotation about several axes.
    """
    if n < 3:
        raise ValueError("a hand-eye calibration needs at least 3 views")
    rng = np.random.default_rng(seed)
    center = np.asarray(board_center, dtype=float)
    base_az = arm_side_azimuth_deg(center)
    out = []
    for i in range(n):
        f = (i + 0.5) / n
        az = base_az + azimuth_span_deg * (((i * 0.618034) % 1.0) - 0.5) * 2
        el = elevations_deg[0] + (elevations_deg[1] - elevations_deg[0]) * f
        d = rng.uniform(*distances)
        T = camera_pose_looking_at(center, d, el, az)
        roll = np.radians(rng.uniform(-roll_deg, roll_deg))
        out.append(T @ make_transform(rotation_about_axis([0, 0, 1], roll)))
    return out
