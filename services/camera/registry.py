"""Camera backend registry: backend name -> its folder's ``CAMERA`` entry (config class + factory).

The same shape as the arm's (``services/arm/drivers/registry.py``), after LeRobot's ``cameras/``: a new
backend is one folder under ``services/camera/`` whose ``__init__`` defines ``CAMERA = CameraEntry(...)``,
plus one line in ``BACKENDS``. The service, the CLI and compose name backends from ``BACKENDS`` only; a
folder is imported only when chosen, so the sim cell never needs pyrealsense2. A backend's options
(``--option KEY=VALUE`` on the camera service) are the fields of its options dataclass
(``common/backend_options.py``): the registry parses them, the backend never sees a string.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from common.backend_options import parse_options
from services.camera.base import Camera, CameraConfig
from services.camera.errors import CameraConfigError

BACKENDS: dict[str, str] = {
    "sim": "services.camera.sim",
    "realsense": "services.camera.realsense",
    "replay": "services.camera.replay",
    "png_folder": "services.camera.png_folder",
}


@dataclass
class CameraContext:
    """What a factory may need from its caller: the twin's render call (sim), an ``rs.device`` to use
    instead of searching USB (realsense: an emulated D435, ``bench/software_d435.py``)."""

    render_request: Any = None
    device: Any = None


@dataclass(frozen=True)
class CameraEntry:
    """One backend: its options dataclass (``options_class``), ``build_config(options) -> config`` (an
    instance of ``config_class``), ``factory(config, context) -> Camera`` (not connected)."""

    name: str
    config_class: type[CameraConfig]
    options_class: type
    """The backend's ``--option`` keys with their types, defaults and help (``common/backend_options.py``)."""
    build_config: Callable[[Any], CameraConfig]
    factory: Callable[[Any, CameraContext], Camera]
    description: str = ""

    def options(self, given: Mapping[str, Any]) -> Any:
        """``given`` (``--option`` strings or typed values) as this backend's options; ``unknown_option`` /
        ``bad_option`` (``CameraConfigError``) name its valid keys."""
        return parse_options(self.options_class, given, backend=f"camera backend {self.name}",
                             error=CameraConfigError)

    def config_from_options(self, given: Mapping[str, Any]) -> CameraConfig:
        """The backend's config from its options (parsed, then built)."""
        return self.build_config(self.options(given))


def camera_entry(name: Any) -> CameraEntry:
    """The registry entry of backend ``name``; ``bad_config`` naming the known ones otherwise."""
    if not isinstance(name, str) or name not in BACKENDS:
        raise CameraConfigError(f"unknown camera backend {name!r}; choose one of {sorted(BACKENDS)}",
                                detail={"backend": name, "known": sorted(BACKENDS)})
    entry = importlib.import_module(BACKENDS[name]).CAMERA
    assert isinstance(entry, CameraEntry) and entry.name == name
    return entry


def config_from_dict(data: dict[str, Any]) -> CameraConfig:
    """``{"backend": "realsense", "width": 848, ...}`` -> ``RealSenseCameraConfig(width=848, ...)``.

    Unknown backends and unknown keys are rejected (a typo must not silently fall back to a default).
    """
    data = dict(data)
    backend = data.pop("backend", None)
    cls = camera_entry(backend).config_class
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
    entry = camera_entry(type(config).backend)
    if not isinstance(config, entry.config_class):
        raise CameraConfigError(f"unknown camera config {type(config).__name__}")
    return entry.factory(config, CameraContext(render_request=render_request, device=device))


def camera_from_options(name: str, options: dict[str, Any], context: CameraContext) -> tuple[Camera, CameraEntry]:
    """The backend ``name`` built from the service's ``options``: (camera, its registry entry)."""
    entry = camera_entry(name)
    return entry.factory(entry.config_from_options(options), context), entry


