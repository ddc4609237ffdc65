"""Typed errors that cross the wire.

Every failure a service reports has a stable ``code`` a caller can branch on, a human ``message`` and a
``detail`` map with the specifics (field name, expected shape, ...). Handlers raise these; the service
runtime turns any exception into an ``Error`` reply, so a bad request never takes a service down.
"""

from __future__ import annotations

from typing import Any


class ObjscanError(Exception):
    """Base class of every error objscan reports; carries a stable code for callers to branch on."""

    code = "error"

    def __init__(self, message: str, *, code: str | None = None, detail: dict[str, Any] | None = None):
        super().__init__(message)
        self.message = message
        if code is not None:
            self.code = code
        self.detail = detail or {}

    def __str__(self) -> str:
        extra = f" {self.detail}" if self.detail else ""
        return f"[{self.code}] {self.message}{extra}"


class WireError(ObjscanError):
    """A message could not be decoded or failed validation (malformed, wrong dtype or shape, NaN, ...)."""

    code = "bad_message"


class RemoteError(ObjscanError):
    """A service answered a request with an ``Error`` reply; ``code`` is the remote one."""

    code = "remote_error"

    @property
    def transient(self) -> bool:
        """The service answered, but one it depends on is going away or not back yet: worth sending again."""
        return self.code in TRANSIENT_REMOTE_CODES


TRANSIENT_REMOTE_CODES = frozenset({"shutdown", "unavailable", "timeout"})


class ServiceUnavailable(ObjscanError):
    """No live service answered a request (nothing declared the key, or it timed out)."""

    code = "unavailable"


class RouterUnreachable(ServiceUnavailable):
    """The Zenoh session could not be opened: no router or peer answers at the configured endpoints."""

    code = "no_router"


class RequestTimeout(ServiceUnavailable):
    """The request was sent but no reply came within its timeout."""

    code = "timeout"


class InvalidRequest(ObjscanError):
    """The request decoded fine but asks for something the service cannot do (e.g. empty cloud)."""

    code = "invalid_request"


class ServiceStartError(ObjscanError):
    """A service process ended before it was live. ``code`` is the service's own (``object_not_found`` when the
    twin could not load its object) when it said why (``common/fatal.py``), else ``service_exited``;
    ``detail`` names the ``service`` and its ``log``."""

    code = "service_exited"
