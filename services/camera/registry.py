"""Camera backend registry: backend name -> its folder's ``CAMERA`` entry (config class + factory).

The same shape as the arm's (``services/arm/drivers/registry.py``), after LeRobot's ``cameras/``: a new
backend is one folder under ``services/camera/`` whose ``__init__`` defines ``CAMERA = CameraEntry(...)``,
plus one line in ``BACKENDS``. The service, the CLI and compose name backends from ``BACKENDS`` only; a
folder is imported only when chosen, so the sim cell never needs pyrealsense2.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

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
    """One backend: ``config_from_options(options) -> config`` (an instance of ``config_class``, from the
    service's command-line/environment options), ``factory(config, context) -> Camera`` (not connected)."""

    name: str
    config_class: type[CameraConfig]
    config_from_options: Callable[[dict[str, Any]], CameraConfig]
    factory: Callable[[Any, CameraContext], Camera]
    description: str = ""
    options: dict[str, str] = field(default_factory=dict)
    """Service options the backend reads (name -> what it means), for ``--help`` and docs/extending.md."""


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


def backend_option(text: str) -> tuple[str, str]:
    """``KEY=VALUE`` from the command line (``--option``) -> (key, value); the backend's
    ``config_from_options`` converts the value, so a new backend needs no new flag."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise ValueError(f"expected KEY=VALUE, got {text!r}")
    return key.strip().replace("-", "_"), value
