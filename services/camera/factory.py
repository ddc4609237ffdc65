"""Build a camera from a config (or a plain dict, as read from a config file or the CLI)."""

from __future__ import annotations

import dataclasses
from typing import Any

from services.camera.base import Camera, CameraConfig
from services.camera.errors import CameraConfigError
from services.camera.realsense.config import RealSenseCameraConfig
from services.camera.replay.config import ReplayCameraConfig
from services.camera.sim.config import SimCameraConfig

CONFIGS: dict[str, type[CameraConfig]] = {
    SimCameraConfig.backend: SimCameraConfig,
    RealSenseCameraConfig.backend: RealSenseCameraConfig,
    ReplayCameraConfig.backend: ReplayCameraConfig,
}
"""Backend name -> its config class."""


def config_from_dict(data: dict[str, Any]) -> CameraConfig:
    """``{"backend": "realsense", "width": 848, ...}`` -> ``RealSenseCameraConfig(width=848, ...)``.

    Unknown backends and unknown keys are rejected (a typo must not silently fall back to a default).
    """
    data = dict(data)
    backend = data.pop("backend", None)
    cls = CONFIGS.get(backend) if isinstance(backend, str) else None
    if cls is None:
        raise CameraConfigError(f"unknown camera backend {backend!r}; choose one of {sorted(CONFIGS)}",
                                detail={"backend": backend})
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise CameraConfigError(f"unknown {backend} camera option(s) {unknown}; known: {sorted(known)}",
                                detail={"unknown": unknown})
    try:
        return cls(**data)
    except TypeError as exc:
        raise CameraConfigError(f"bad {backend} camera config: {exc}") from None


def make_camera(config: CameraConfig | dict[str, Any], *, render_request: Any = None,
                device: Any = None) -> Camera:
    """The camera for ``config.backend`` (not yet connected).

    ``render_request`` is required by the sim backend (the twin's render call); ``device`` optionally
    hands the realsense backend an ``rs.device`` (e.g. a software D435) instead of searching USB.
    """
    if isinstance(config, dict):
        config = config_from_dict(config)
    if isinstance(config, SimCameraConfig):
        from services.camera.sim.camera import SimCamera

        if render_request is None:
            raise CameraConfigError("the sim camera needs render_request (the twin's render call)")
        return SimCamera(config, render_request=render_request)
    if isinstance(config, RealSenseCameraConfig):
        from services.camera.realsense.camera import RealSenseCamera

        return RealSenseCamera(config, device=device)
    if isinstance(config, ReplayCameraConfig):
        from services.camera.replay.camera import ReplayCamera

        return ReplayCamera(config)
    raise CameraConfigError(f"unknown camera config {type(config).__name__}")
