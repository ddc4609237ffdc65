"""Typed failures of ``objscan import`` (an ``ObjscanError`` each, with a stable code)."""

from __future__ import annotations

from common.errors import ObjscanError


class ImportError_(ObjscanError):  # noqa: N801 - not the builtin ImportError
    """The sequence cannot be imported: no frames, unpaired images, bad intrinsics, no table in view."""

    code = "import_failed"
