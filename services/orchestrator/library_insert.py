"""The finished model into the model library: the last, optional step of an acquisition.

Its own module so the state machine only asks "insert this session" and gets the entry or the reason it
could not: a library failure never fails the acquisition, the session folder keeps the model.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class LibraryInsert:
    """What became of the insert: the library entry, or the error (shortened) that kept the model out."""

    entry: Any = None
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


def insert_session_model(library: Path, session: Path) -> LibraryInsert:
    """Add the session's model to the library at ``library`` (files and descriptors: CPU and disk, so the
    machine calls ``insert_session_model_async``). Never raises: any failure comes back as ``error``."""
    try:
        from services.library import add_session_model  # on first use: it loads the descriptor code

        return LibraryInsert(entry=add_session_model(library, session))
    except Exception as exc:  # noqa: BLE001 - the session folder keeps the model: nothing is lost
        return LibraryInsert(error=repr(exc)[:300])


async def insert_session_model_async(library: Path, session: Path) -> LibraryInsert:
    """``insert_session_model`` in a thread, so the event loop keeps serving status and stop requests."""
    return await asyncio.to_thread(insert_session_model, library, session)
