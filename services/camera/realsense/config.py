"""Configuration of the RealSense (D435) backend."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from services.camera.base import CameraConfig
from services.camera.errors import CameraConfigError


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

    def __post_init__(self) -> None:
        for name in ("width", "height", "fps", "frames_per_capture", "timeout_ms"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
                raise CameraConfigError(f"{name} must be a positive integer", detail={name: value})
        if not isinstance(self.warmup_frames, int) or self.warmup_frames < 0:
            raise CameraConfigError("warmup_frames must be a non-negative integer",
                                    detail={"warmup_frames": self.warmup_frames})
