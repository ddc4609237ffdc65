"""Sim backend: frames rendered by the digital twin through an injected render request.

Options: ``width``/``height`` (a D435 colour preset). The service waits up to 60 s for a render: the twin
renders in ~60 ms, but a loaded 2-core machine can stall it for seconds.
"""

from __future__ import annotations

from services.camera.errors import CameraConfigError
from services.camera.registry import CameraContext, CameraEntry
from services.camera.sim.camera import RenderRequest, SimCamera
from services.camera.sim.config import SimCameraConfig, SimCameraOptions

SERVICE_TIMEOUT_S = 60.0


def _config(options: SimCameraOptions) -> SimCameraConfig:
    return SimCameraConfig(width=options.width, height=options.height, timeout_s=SERVICE_TIMEOUT_S)


def _factory(config: SimCameraConfig, ctx: CameraContext) -> SimCamera:
    if ctx.render_request is None:
        raise CameraConfigError("the sim camera needs render_request (the twin's render call)")
    return SimCamera(config, render_request=ctx.render_request)


CAMERA = CameraEntry("sim", SimCameraConfig, SimCameraOptions, _config, _factory,
                     description="frames rendered by the digital twin (services/sim)")

__all__ = ["CAMERA", "RenderRequest", "SimCamera", "SimCameraConfig"]
