"""RealSense D435 backend (pyrealsense2): live camera, .db3 playback, or an injected ``rs.device`` (an emulated D435).

Options: ``width``/``height``, ``serial``, ``visual_preset``, ``no_exposure_lock``, ``playback`` (a .db3).
Its frames are stamped with the pose the arm believes (``pose_from_arm``).
"""

from __future__ import annotations

from typing import Any

from services.camera.realsense.camera import RealSenseCamera
from services.camera.realsense.config import RealSenseCameraConfig
from services.camera.registry import CameraContext, CameraEntry


def _config(options: dict[str, Any]) -> RealSenseCameraConfig:
    config = RealSenseCameraConfig(width=options.get("width", 640), height=options.get("height", 480),
                                   serial=options.get("serial"),
                                   visual_preset=options.get("visual_preset", "high_accuracy"),
                                   lock_exposure=not options.get("no_exposure_lock", False))
    if options.get("playback"):
        config.playback_file = options["playback"]
    return config


def _factory(config: RealSenseCameraConfig, ctx: CameraContext) -> RealSenseCamera:
    return RealSenseCamera(config, device=ctx.device)


CAMERA = CameraEntry("realsense", RealSenseCameraConfig, _config, _factory,
                     description="an Intel RealSense D435 (or a .db3 recording of one)",
                     options={"width": "image width", "height": "image height",
                              "serial": "which camera when several are attached",
                              "visual_preset": "D400 depth preset (None leaves the camera's)",
                              "no_exposure_lock": "keep auto exposure on", "playback": "a .db3 to play"})

__all__ = ["CAMERA", "RealSenseCamera", "RealSenseCameraConfig"]
