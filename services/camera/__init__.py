"""The camera service's backends: one ``Camera`` interface, one folder per backend, named in
``registry.BACKENDS`` (``sim`` | ``realsense`` | ``replay`` | ``png_folder``).

``make_camera(config)`` builds one; see docs/camera.md and docs/extending.md.
"""

from services.camera.base import Camera, CameraConfig, check_frame, check_pose
from services.camera.errors import (
    BadFrameError,
    BadPoseError,
    CameraConfigError,
    CameraError,
    CaptureTimeout,
    EndOfReplay,
    NoDeviceError,
    NotConnectedError,
    ReplayDataError,
)
from services.camera.realsense.config import RealSenseCameraConfig
from services.camera.registry import BACKENDS, CameraContext, CameraEntry, camera_entry, config_from_dict, make_camera
from services.camera.replay.config import ReplayCameraConfig
from services.camera.sim.config import SimCameraConfig

__all__ = [
    "BACKENDS", "BadFrameError", "BadPoseError", "Camera", "CameraConfig", "CameraConfigError", "CameraContext",
    "CameraEntry", "CameraError", "CaptureTimeout", "EndOfReplay", "NoDeviceError", "NotConnectedError",
    "RealSenseCameraConfig", "ReplayCameraConfig", "ReplayDataError", "SimCameraConfig", "camera_entry",
    "check_frame", "check_pose", "config_from_dict", "make_camera",
]
