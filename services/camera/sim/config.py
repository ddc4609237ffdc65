"""Configuration of the sim backend."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from common.backend_options import option
from services.camera.base import CameraConfig
from services.camera.errors import CameraConfigError
from services.camera.intrinsics import d435_color_intrinsics


@dataclass(frozen=True)
class SimCameraOptions:
    """``--option KEY=VALUE`` on the camera service (``--width``/``--height`` set the same two)."""

    width: int = option(640, "image width in pixels (640 or 848)")
    height: int = option(480, "image height in pixels (480)")


@dataclass
class SimCameraConfig(CameraConfig):
    """Render size (a D435 color preset: 640x480 or 848x480) and how long to wait for the twin."""

    backend: ClassVar[str] = "sim"

    width: int = 640
    height: int = 480
    timeout_s: float = 10.0

    def __post_init__(self) -> None:
        d435_color_intrinsics(self.width, self.height)  # raises bad_config for a size with no preset
        if not (isinstance(self.timeout_s, (int, float)) and self.timeout_s > 0):
            raise CameraConfigError("timeout_s must be positive", detail={"timeout_s": self.timeout_s})
