"""Storing an export with the library entry its acquisition made, shared by ``objscan export`` and ``scan --export``.

Its own module so that neither command imports the other (the export already imports the scan's console).
"""

from __future__ import annotations

import sys
from pathlib import Path

from common.errors import ObjscanError
from services.cli.outcome import one_line


def store_with_library_entry(session: Path, command: str) -> str | None:
    """The export's mesh and asset stored with the library entry the acquisition made (if it made one).

    The files are written either way: a library that cannot take them costs a warning line, not the export.
    """
    from services.library import attach_session_export

    try:
        return attach_session_export(session)
    except ObjscanError as exc:
        print(one_line(f"objscan {command}: WARNING: the export is not stored with the library entry: "
                       f"{exc.message} [{exc.code}]"), file=sys.stderr)
        return None
