"""The D435 colour modes the camera accepts.

The colour model itself (fx = fy = 615 px at 480 rows, principal point at the centre) is defined once,
``common.messages.d435_intrinsics``: the twin renders with it and the sim backend checks against it. A real
D435 reports its own factory calibration and the realsense backend always uses that (an emulated D435's
depth imager is described in ``bench/software_d435.py``).
"""

from __future__ import annotations

from common.messages import D435_COLOR_SIZES, Intrinsics, d435_intrinsics
from services.camera.errors import CameraConfigError


def d435_color_intrinsics(width: int = 640, height: int = 480) -> Intrinsics:
    """Typical D435 color intrinsics for a colour mode of ``D435_COLOR_SIZES`` (``bad_config`` otherwise)."""
    if (width, height) not in D435_COLOR_SIZES:
        sizes = ", ".join(f"{w}x{h}" for w, h in D435_COLOR_SIZES)
        raise CameraConfigError(f"no D435 color preset for {width}x{height}; known: {sizes}",
                                detail={"width": width, "height": height})
    return d435_intrinsics(width, height)
