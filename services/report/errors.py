"""Typed errors of the session report."""

from __future__ import annotations

from common.errors import ObjscanError


class ReportError(ObjscanError):
    """The report cannot be made (no session there, nothing renderable, bad render arguments)."""

    code = "report_error"
