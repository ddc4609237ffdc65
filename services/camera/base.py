"""The one camera interface every backend implements, plus the checks they all share.

Modelled on LeRobot's ``cameras/``: an abstract ``Camera``, one folder per backend, each with its own config
dataclass. The base class owns the state machine (connect -> capture* -> disconnect), the sequence
counter and the validation of what goes in (the pose) and what comes out (the frame), so a backend only
implements ``_open``, ``_grab`` and ``_close`` and cannot hand the pipeline a malformed frame.

Capturing is synchronous (pyrealsense2 and file reads block); ``acapture`` is the asyncio face the service
calls. Its default runs ``capture`` in a worker thread; the sim backend overrides it to await its render
request directly on the event loop.
"""

from __future__ import annotations

import asyncio
import threading
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from common.errors import WireError
from common.geometry import as_rigid_transform
from common.messages import RGBDFrame
from services.camera.errors import BadFrameError, BadPoseError, CameraError, NotConnectedError

POSE_SOURCE_KEY = "pose_source"
"""``frame.meta`` key saying where ``T_base_camera`` came from: ``given`` (passed to capture), ``recorded``
(replay), ``sim`` (the twin's belief), or ``unknown`` (no pose was given: the identity stands in)."""

LIVE_POSE_SOURCES = ("given", "sim")
"""Pose sources of a live frame, which a hand-eye calibration corrects; a recorded pose was stamped (and
corrected) when recorded, and an unknown one must stay recognisable as the identity."""


@dataclass
class CameraConfig:
    """Base of the backend configs; ``backend`` names the backend a config belongs to."""

    backend: ClassVar[str] = ""


def check_pose(T: Any) -> np.ndarray | None:
    """Return ``T`` as a float64 4x4 rigid transform (or None), or raise ``BadPoseError``.

    A wrong pose would silently corrupt every registration downstream, so it is rejected at the door.
    """
    if T is None:
        return None
    return as_rigid_transform(T, "camera pose", BadPoseError, class_code=True)


def check_frame(frame: Any, *, expected_size: tuple[int, int] | None = None) -> RGBDFrame:
    """Validate a frame a backend produced or received; raise ``BadFrameError`` with the reason.

    Checks types, dtypes and shapes (color uint8 HxWx3, depth uint16 HxW, equal sizes, intrinsics of the
    same size), a positive finite depth scale and a finite 4x4 pose; ``expected_size`` is (width, height).
    """
    if not isinstance(frame, RGBDFrame):
        raise BadFrameError(f"expected an RGBDFrame, got {type(frame).__name__}")
    color, depth = frame.color, frame.depth
    if not isinstance(color, np.ndarray) or color.dtype != np.uint8 or color.ndim != 3 or color.shape[2] != 3:
        raise BadFrameError("color must be a uint8 HxWx3 array",
                            detail={"dtype": str(getattr(color, "dtype", None)),
                                    "shape": list(getattr(color, "shape", ()))})
    if not isinstance(depth, np.ndarray) or depth.dtype != np.uint16 or depth.ndim != 2:
        raise BadFrameError("depth must be a uint16 HxW array",
                            detail={"dtype": str(getattr(depth, "dtype", None)),
                                    "shape": list(getattr(depth, "shape", ()))})
    if depth.size == 0:
        raise BadFrameError("frame is empty", detail={"shape": list(depth.shape)})
    try:
        frame.intrinsics.validate()
        frame.validate()
    except WireError as exc:
        raise BadFrameError(exc.message, detail={"reason": exc.code, **exc.detail}) from None
    if not np.isfinite(frame.depth_scale):
        raise BadFrameError("depth_scale is not finite")
    T = np.asarray(frame.T_base_camera)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise BadFrameError("T_base_camera must be a finite 4x4 matrix", detail={"shape": list(T.shape)})
    if expected_size is not None and (depth.shape[1], depth.shape[0]) != tuple(expected_size):
        raise BadFrameError("frame size differs from the requested size",
                            detail={"got": [depth.shape[1], depth.shape[0]], "expected": list(expected_size)})
    return frame


class Camera(ABC):
    """One RGB-D camera: ``connect()``, then any number of ``capture()``, then ``disconnect()``.

    ``capture(T_base_camera)`` takes the camera pose in ``base`` as the robot believes it (FK + hand-eye,
    computed by the service) and returns an aligned ``RGBDFrame`` stamped with it. Backends that know
    better (replay: the recorded pose) say so in ``frame.meta['pose_source']``.
    """

    pose_from_arm: ClassVar[bool] = False
    """True when the backend stamps the pose passed to ``capture``: the service then asks the arm for it
    (a real camera knows nothing of where it is; the twin and a replay know better)."""

    def __init__(self, config: CameraConfig):
        self.config = config
        self._connected = False
        self._seq = 0
        self._lock = threading.RLock()  # one capture at a time: the service may get concurrent requests

    # ---------------------------------------------------------------- what a backend implements
    @abstractmethod
    def _open(self) -> None:
        """Acquire the device / files / peer; raise a ``CameraError`` when impossible."""

    @abstractmethod
    def _grab(self, T_base_camera: np.ndarray | None) -> RGBDFrame:
        """Produce one frame (``seq`` is filled by the caller)."""

    @abstractmethod
    def _close(self) -> None:
        """Release what ``_open`` acquired; must not raise."""

    def _info(self) -> dict[str, Any]:
        """Backend-specific facts for ``info()`` (device name, serial, file, ...)."""
        return {}

    # ---------------------------------------------------------------- the public face
    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self) -> None:
        """Open the camera; calling it twice is harmless."""
        with self._lock:
            if self._connected:
                return
            self._open()
            self._connected = True

    def disconnect(self) -> None:
        """Release the camera; calling it twice (or before connect) is harmless."""
        with self._lock:
            if not self._connected:
                return
            try:
                self._close()
            finally:
                self._connected = False

    def capture(self, T_base_camera: np.ndarray | None = None) -> RGBDFrame:
        """Capture one aligned RGB-D frame stamped with ``T_base_camera`` (validated) and the next seq."""
        with self._lock:
            T = self._before_capture(T_base_camera)
            return self._after_capture(self._grab(T))

    async def acapture(self, T_base_camera: np.ndarray | None = None) -> RGBDFrame:
        """Asyncio face of ``capture``: runs the blocking capture in a worker thread."""
        return await asyncio.to_thread(self.capture, T_base_camera)

    async def aconnect(self) -> None:
        """Asyncio face of ``connect`` (a RealSense warm-up blocks for about a second)."""
        await asyncio.to_thread(self.connect)

    def info(self) -> dict[str, Any]:
        """What the service reports about its camera: backend, state, frames served, backend facts."""
        out: dict[str, Any] = {"backend": type(self.config).backend, "connected": self._connected,
                               "frames": self._seq}
        out.update(self._info())
        return out

    def __enter__(self) -> Camera:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.disconnect()

    # ---------------------------------------------------------------- shared plumbing
    def _before_capture(self, T_base_camera: Any) -> np.ndarray | None:
        if not self._connected:
            raise NotConnectedError(f"{type(self).__name__} is not connected: call connect() first")
        return check_pose(T_base_camera)

    def _after_capture(self, frame: RGBDFrame) -> RGBDFrame:
        check_frame(frame)
        self._seq += 1
        return frame

    def _next_seq(self) -> int:
        """Sequence number the frame being captured gets (0 for the first capture)."""
        return self._seq


def stamp_pose(frame_meta: dict[str, Any], T_given: np.ndarray | None) -> np.ndarray:
    """The pose to stamp on a live frame: the given one, else the identity marked ``unknown`` in meta."""
    if T_given is None:
        frame_meta[POSE_SOURCE_KEY] = "unknown"
        return np.eye(4)
    frame_meta[POSE_SOURCE_KEY] = "given"
    return T_given.copy()


__all__ = ["LIVE_POSE_SOURCES", "POSE_SOURCE_KEY", "Camera", "CameraConfig", "CameraError", "check_frame", "check_pose",
           "stamp_pose"]
