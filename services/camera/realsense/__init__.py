"""RealSense D435 backend (pyrealsense2): live camera, .db3 playback, or an injected ``rs.device`` (an emulated D435).

Options: ``width``/``height``, ``serial``, ``visual_preset``, ``no_exposure_lock``, ``playback`` (a .db3).
Its frames are stamped with the pose the arm believes (``pose_from_arm``).
"""

from __future__ import annotations

from services.camera.realsense.camera import RealSenseCamera
from services.camera.realsense.config import RealSenseCameraConfig, RealSenseOptions
from services.camera.registry import CameraContext, CameraEntry


def _config(options: RealSenseOptions) -> RealSenseCameraConfig:
    config = RealSenseCameraConfig(width=options.width, height=options.height, serial=options.serial,
                                   visual_preset=options.visual_preset, lock_exposure=not options.no_exposure_lock)
    if options.playback:
        config.playback_file = options.playback
    return config


def _factory(config: RealSenseCameraConfig, ctx: CameraContext) -> RealSenseCamera:
    return RealSenseCamera(config, device=ctx.device)


CAMERA = CameraEntry("realsense", RealSenseCameraConfig, RealSenseOptions, _config, _factory,
                     description="an Intel RealSense D435 (or a .db3 recording of one)")

__all__ = ["CAMERA", "RealSenseCamera", "RealSenseCameraConfig"]
