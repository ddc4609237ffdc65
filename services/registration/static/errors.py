"""Typed failures of static registration and object isolation.

Each has a stable ``code`` a caller (the registration service face, the orchestrator) can branch on: an
empty depth image means "capture again", no table means "the camera is not looking at the workspace",
no object means "nothing stands where we looked".
"""

from __future__ import annotations

from common.errors import ObjscanError


class StaticRegistrationError(ObjscanError):
    """Base of every static-registration failure."""

    code = "static_registration_failed"


class BadFramesError(StaticRegistrationError):
    """The frames given cannot be used at all (none, wrong shapes, NaN pose, inconsistent inputs)."""

    code = "bad_frames"


class EmptyDepthError(StaticRegistrationError):
    """A frame's depth holds no usable return (all zero or all outside the depth range)."""

    code = "empty_depth"


class NoTableError(StaticRegistrationError):
    """No supporting plane was found: too few plane inliers, or the plane is not horizontal."""

    code = "no_table"


class NoObjectError(StaticRegistrationError):
    """Nothing of object size stands on the table where the camera looks."""

    code = "no_object"


class RegistrationFailedError(StaticRegistrationError):
    """Neither the local nor the global registration of a scan passed the quality check."""

    code = "registration_failed"
