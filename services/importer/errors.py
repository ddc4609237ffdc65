"""Typed failures of ``objscan import`` (an ``ObjscanError`` each, with a stable code)."""

from __future__ import annotations

from common.errors import ObjscanError


class ImportError_(ObjscanError):  # noqa: N801 - not the builtin ImportError
    """The sequence cannot be imported: no frames, unpaired images, bad intrinsics, no table in view."""

    code = "import_failed"


class OutNotEmpty(ImportError_):
    """``--out`` names a file or a folder that already holds something: an import writes only into an absent or
    empty folder (as a new scan does), so it never merges into, or half-replaces, another session."""

    code = "out_not_empty"
