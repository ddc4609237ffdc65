"""The sim backend: ask the digital twin (the sim service, another process) to render a D435 frame.

The call to the twin is injected as ``render_request(T_base_camera_or_None, width, height) -> RGBDFrame``
(plain or async), so this backend is testable without Zenoh; the service face injects a Zenoh request
to ``objscan/{robot}/sim/render``. The twin knows the true camera pose (``T_base_camera_true``); the pose
passed to ``capture`` is the robot's belief (FK + hand-eye) and is what the frame is stamped with. With no
pose given, the twin's own belief is kept (``meta['pose_source'] = 'sim'``).

Whatever the twin sends back is validated (type, dtypes, shapes, size asked for, intrinsics, pose)
before it reaches the pipeline: a broken twin gives ``bad_frame``, a silent one ``timeout``.
"""

from __future__ import annotations

import asyncio
import inspect
import time
from collections.abc import Awaitable, Callable
from typing import Any

import numpy as np

from common.messages import Intrinsics, RGBDFrame
from services.camera.base import POSE_SOURCE_KEY, Camera, check_frame
from services.camera.errors import CameraConfigError, CameraError, CaptureTimeout
from services.camera.intrinsics import d435_color_intrinsics
from services.camera.sim.config import SimCameraConfig

RenderRequest = Callable[[np.ndarray | None, int, int], "RGBDFrame | Awaitable[RGBDFrame]"]


class SimCamera(Camera):
    """A D435 rendered by the digital twin through an injected ``render_request``."""

    config: SimCameraConfig

    def __init__(self, config: SimCameraConfig | None = None, *, render_request: RenderRequest | None = None):
        super().__init__(config or SimCameraConfig())
        self.render_request = render_request
        self._alock: asyncio.Lock | None = None

    @property
    def intrinsics(self) -> Intrinsics:
        """The D435 color preset the twin is expected to render with (services/camera/intrinsics.py)."""
        return d435_color_intrinsics(self.config.width, self.config.height)

    def _open(self) -> None:
        if not callable(self.render_request):
            raise CameraConfigError("the sim backend needs a render_request callable (the twin render call)")

    def _close(self) -> None:
        pass

    def _size(self) -> tuple[int, int]:
        return self.config.width, self.config.height

    # -------------------------------------------------------------------------------- sync capture
    def _grab(self, T_base_camera: np.ndarray | None) -> RGBDFrame:
        result = self.render_request(T_base_camera, *self._size())
        if inspect.isawaitable(result):
            try:
                asyncio.get_running_loop()
            except RuntimeError:
                result = asyncio.run(self._await(result))
            else:
                if inspect.iscoroutine(result):
                    result.close()
                raise CameraError("the sim render_request is async and an event loop is running in this "
                                  "thread: call `await camera.acapture(...)` instead", code="use_acapture")
        return self._finish(result, T_base_camera)

    # ------------------------------------------------------------------------------- async capture
    async def acapture(self, T_base_camera: np.ndarray | None = None) -> RGBDFrame:
        """Await the render on the running loop (async render_request) or in a worker thread (plain).

        Concurrent calls are served one after the other, so sequence numbers follow the order of renders.
        """
        if self._alock is None:
            self._alock = asyncio.Lock()
        async with self._alock:
            return await self._acapture(T_base_camera)

    async def _acapture(self, T_base_camera: np.ndarray | None) -> RGBDFrame:
        T = self._before_capture(T_base_camera)
        if inspect.iscoroutinefunction(self.render_request):
            result: Any = self.render_request(T, *self._size())
        else:
            result = await self._await(asyncio.to_thread(self.render_request, T, *self._size()))
        if inspect.isawaitable(result):
            result = await self._await(result)
        return self._after_capture(self._finish(result, T))

    async def _await(self, awaitable: Awaitable[Any]) -> Any:
        try:
            return await asyncio.wait_for(awaitable, timeout=self.config.timeout_s)
        except TimeoutError:
            raise CaptureTimeout(f"the digital twin did not render within {self.config.timeout_s} s",
                                 detail={"timeout_s": self.config.timeout_s}) from None

    # ------------------------------------------------------------------------------------- checks
    def _finish(self, frame: Any, T_given: np.ndarray | None) -> RGBDFrame:
        check_frame(frame, expected_size=self._size())
        meta = dict(frame.meta or {})
        if T_given is not None:
            frame.T_base_camera = T_given.copy()
            meta[POSE_SOURCE_KEY] = "given"
        else:
            frame.T_base_camera = np.asarray(frame.T_base_camera, dtype=np.float64)
            meta[POSE_SOURCE_KEY] = "sim"
        frame.meta = meta
        frame.seq = self._next_seq()
        if not frame.stamp:
            frame.stamp = time.time()
        return frame

    def _info(self) -> dict[str, Any]:
        return {"width": self.config.width, "height": self.config.height,
                "intrinsics": self.intrinsics.as_dict()}
