"""Sim backend: frames rendered by the digital twin through an injected render request."""

from services.camera.sim.camera import RenderRequest, SimCamera
from services.camera.sim.config import SimCameraConfig

__all__ = ["RenderRequest", "SimCamera", "SimCameraConfig"]
