"""Typed errors of the export step: a session that cannot be turned into a mesh says why, with a stable code."""

from __future__ import annotations

from common.errors import ObjscanError


class ExportError(ObjscanError):
    """The export could not produce its files (a surface that does not close, a writer that failed)."""

    code = "export_failed"


class ExportInputError(ExportError):
    """The session lacks what the export reads (no model, no registered view poses, a bad argument)."""

    code = "bad_export_input"
