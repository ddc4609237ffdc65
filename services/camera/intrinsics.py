"""The D435 colour modes the camera accepts, and the depth-imager presets of the software-device tests.

The colour model itself (fx = fy = 615 px at 480 rows, principal point at the centre) is defined once,
``common.messages.d435_intrinsics``: the twin renders with it and the sim backend checks against it. A real
D435 reports its own factory calibration and the realsense backend always uses that. The depth presets and
the depth-to-color offset are used only to emulate an unaligned D435 (pyrealsense2 software device) in tests.
"""

from __future__ import annotations

import numpy as np

from common.messages import D435_COLOR_SIZES, Intrinsics, d435_intrinsics
from services.camera.errors import CameraConfigError

D435_DEPTH_PRESETS: dict[tuple[int, int], tuple[float, float, float, float]] = {
    (640, 480): (383.0, 383.0, 320.0, 240.0),
    (848, 480): (424.0, 424.0, 424.0, 240.0),
}
"""(width, height) -> (fx, fy, cx, cy) of the D435 depth (left IR) camera: wider field of view than color."""

D435_DEPTH_TO_COLOR_TRANSLATION_M = (0.015, 0.0, 0.0)
"""Translation of the depth -> color extrinsics a D435 typically reports (p_color = p_depth + t), m."""

D435_DEPTH_SCALE = 0.001
"""Metres per depth unit of a D435 at its default setting."""


def _lookup(presets: dict[tuple[int, int], tuple[float, float, float, float]], width: int, height: int,
            what: str) -> Intrinsics:
    try:
        fx, fy, cx, cy = presets[(int(width), int(height))]
    except KeyError:
        sizes = ", ".join(f"{w}x{h}" for w, h in presets)
        raise CameraConfigError(f"no D435 {what} preset for {width}x{height}; known: {sizes}",
                                detail={"width": width, "height": height}) from None
    return Intrinsics(width=int(width), height=int(height), fx=fx, fy=fy, cx=cx, cy=cy)


def d435_color_intrinsics(width: int = 640, height: int = 480) -> Intrinsics:
    """Typical D435 color intrinsics for a colour mode of ``D435_COLOR_SIZES`` (``bad_config`` otherwise)."""
    if (width, height) not in D435_COLOR_SIZES:
        sizes = ", ".join(f"{w}x{h}" for w, h in D435_COLOR_SIZES)
        raise CameraConfigError(f"no D435 color preset for {width}x{height}; known: {sizes}",
                                detail={"width": width, "height": height})
    return d435_intrinsics(width, height)


def d435_depth_intrinsics(width: int = 640, height: int = 480) -> Intrinsics:
    """Typical D435 depth-imager intrinsics for a supported size (a fresh object each call)."""
    return _lookup(D435_DEPTH_PRESETS, width, height, "depth")


def d435_T_color_depth() -> np.ndarray:
    """Typical extrinsics ``T_color_depth`` (depth frame -> color frame) of a D435: a pure translation."""
    T = np.eye(4)
    T[:3, 3] = D435_DEPTH_TO_COLOR_TRANSLATION_M
    return T
