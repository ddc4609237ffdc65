"""Typed errors of the digital twin.

Every failure the sim reports carries a stable ``code`` so the service face (and the orchestrator behind
it) can branch on it instead of parsing messages.
"""

from __future__ import annotations

import numpy as np

from common.errors import ObjscanError
from common.geometry import as_rigid_transform


class SimError(ObjscanError):
    """Base class of the sim's errors."""

    code = "sim_error"


class SimObjectError(SimError):
    """An object could not be loaded: unknown name, missing file, unreadable or degenerate mesh.

    Codes: ``object_not_found`` (no such name or file), ``bad_mesh`` (unreadable, empty, NaN or flat),
    ``bad_argument`` (invalid scale or up axis).
    """

    code = "bad_mesh"


class SimInputError(SimError):
    """A caller handed the sim something it cannot use (a non-rigid pose, NaNs, a bad size)."""

    code = "invalid_request"


def check_transform(T: np.ndarray, name: str) -> np.ndarray:
    """Return ``T`` as a float64 4x4 rigid transform, or raise ``SimInputError`` saying what is wrong.

    Every pose entering the twin goes through here: a NaN or a scaled matrix would otherwise silently
    render garbage or corrupt the world state.
    """
    return as_rigid_transform(T, name, SimInputError)
