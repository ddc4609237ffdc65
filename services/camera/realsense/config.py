"""Configuration of the RealSense (D435) backend."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from common.backend_options import option
from services.camera.base import CameraConfig
from services.camera.errors import CameraConfigError
from services.camera.realsense.control import VISUAL_PRESETS


@dataclass(frozen=True)
class RealSenseOptions:
    """``--option KEY=VALUE`` on the camera service (``--width``/``--height`` set the first two)."""

    width: int = option(640, "image width in pixels")
    height: int = option(480, "image height in pixels")
    serial: str | None = option(None, "the camera to open when several are attached", env="OBJSCAN_CAMERA_SERIAL")
    visual_preset: str | None = option("high_accuracy", "D400 depth preset ('none' leaves the camera's)",
                                       env="OBJSCAN_CAMERA_PRESET")
    no_exposure_lock: bool = option(False, "keep auto exposure / white balance on (default: locked after warm-up)")
    playback: str | None = option(None, "play a .db3 recording instead of a live camera")


@dataclass
class RealSenseCameraConfig(CameraConfig):
    """How to open a D435 (or play back a recording of one).

    - ``serial``: pick one camera when several are attached; None takes the first.
    - ``width``/``height``/``fps``: one mode for both depth and color (D435: 640x480 or 848x480 at 6/15/30).
    - ``warmup_frames``: frames dropped after start so auto-exposure settles (~1 s at 30 fps). Not applied
      to playback, which must serve every recorded frame.
    - ``frames_per_capture``: fresh framesets pulled per capture, all through the filters; with the temporal
      filter on, 5 lets it average a static scene. The temporal history is reset at every capture so depth
      from the previous arm pose never leaks into the next.
    - ``spatial_filter``/``temporal_filter``: librealsense's edge-preserving depth filters, applied before
      depth is aligned to color.
    - ``playback_file``: a ``.db3`` (or legacy ``.bag``) recording to play instead of a live camera; it is
      played non-real-time, so every frame is served once, in order, deterministically.
    - ``timeout_ms``: how long a capture waits for a frame before ``timeout``.
    - ``visual_preset``: the depth sensor's D400 preset (``high_accuracy`` by default; None leaves it).
    - ``lock_exposure``: settle auto exposure / white balance during ``warmup_frames``, then switch them
      off and hold those values for the whole run (recorded in every frame's ``meta["exposure"]``).
    - ``timeouts_before_reset``: consecutive frame timeouts after which the camera is ``hardware_reset``
      and its pipeline restarted (a USB drop); 0 never resets. ``reset_wait_s``: time for it to come back.
    """

    backend: ClassVar[str] = "realsense"

    serial: str | None = None
    width: int = 640
    height: int = 480
    fps: int = 30
    warmup_frames: int = 30
    frames_per_capture: int = 1
    spatial_filter: bool = False
    temporal_filter: bool = False
    playback_file: str | None = None
    timeout_ms: int = 5000
    visual_preset: str | None = "high_accuracy"
    lock_exposure: bool = True
    timeouts_before_reset: int = 2
    reset_wait_s: float = 3.0

    def __post_init__(self) -> None:
        for name in ("width", "height", "fps", "frames_per_capture", "timeout_ms"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
                raise CameraConfigError(f"{name} must be a positive integer", detail={name: value})
        if self.visual_preset is not None and self.visual_preset not in VISUAL_PRESETS:
            raise CameraConfigError(f"unknown visual preset {self.visual_preset!r}; known: {', '.join(VISUAL_PRESETS)}",
                                    detail={"visual_preset": self.visual_preset})
        if not isinstance(self.timeouts_before_reset, int) or self.timeouts_before_reset < 0:
            raise CameraConfigError("timeouts_before_reset must be a non-negative integer",
                                    detail={"timeouts_before_reset": self.timeouts_before_reset})
        if not (isinstance(self.reset_wait_s, (int, float)) and 0 <= self.reset_wait_s <= 60):
            raise CameraConfigError("reset_wait_s must be in [0, 60]", detail={"reset_wait_s": self.reset_wait_s})
        if self.serial is not None and not (isinstance(self.serial, str) and self.serial.strip()):
            raise CameraConfigError("serial must be a non-empty string", detail={"serial": self.serial})
        if not isinstance(self.warmup_frames, int) or self.warmup_frames < 0:
            raise CameraConfigError("warmup_frames must be a non-negative integer",
                                    detail={"warmup_frames": self.warmup_frames})
