"""Ground-truth figures of a static registration, where the frames carry truth (the simulator).

Poses are compared *relative to scan 0* (T_c0_cj estimated vs true): the view is anchored on scan 0's
believed pose, and no registration of the view's own images can see that pose's error (hand-eye
calibration), so an absolute comparison would measure the calibration, not the registration.
"""

from __future__ import annotations

from common.geometry import invert, transform_error
from common.messages import RGBDFrame

from .result import StaticViewResult


def relative_pose_errors(result: StaticViewResult, frames: list[RGBDFrame]) -> list[tuple[float, float]] | None:
    """(mm, deg) of each scan j >= 1 relative to scan 0, or None when the frames carry no ground truth."""
    if len(frames) != len(result.scans) or any(f.T_base_camera_true is None for f in frames):
        return None
    T0e, T0t = result.scans[0].T_base_camera, frames[0].T_base_camera_true
    out = []
    for s, f in zip(result.scans[1:], frames[1:], strict=True):
        dt, dr = transform_error(invert(T0e) @ s.T_base_camera, invert(T0t) @ f.T_base_camera_true)
        out.append((dt * 1e3, dr))
    return out


def prior_pose_errors(frames: list[RGBDFrame]) -> list[tuple[float, float]] | None:
    """The same figures for the arm's believed poses alone: the baseline registration must beat."""
    if any(f.T_base_camera_true is None for f in frames):
        return None
    T0b, T0t = frames[0].T_base_camera, frames[0].T_base_camera_true
    out = []
    for f in frames[1:]:
        dt, dr = transform_error(invert(T0b) @ f.T_base_camera, invert(T0t) @ f.T_base_camera_true)
        out.append((dt * 1e3, dr))
    return out
