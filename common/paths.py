"""Paths that arrive over the network, confined to the folders a service was configured with.

The orchestrator's ``run`` request names folders (``out``, ``resume``, ``library``); a path taken as given
would let a request make the orchestrator create, write or tidy folders anywhere
the process may write. ``confine`` resolves a requested path (symlinks and ``..`` included) and refuses
it unless it lies inside the configured root: a typed ``PathNotAllowed`` (code ``path_not_allowed``),
checked before anything is created.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from common.errors import ObjscanError


class PathNotAllowed(ObjscanError):
    """A requested path lies outside the root this service was configured to use."""

    code = "path_not_allowed"


def confine(requested: Any, root: str | Path, *, what: str, allow_root: bool = False) -> Path:
    """``requested`` resolved, if it is inside ``root`` (a relative path is taken relative to ``root``).

    ``allow_root``: the root itself is acceptable (a library folder), not only what is below it (sessions).
    """
    if not isinstance(requested, (str, Path)) or not str(requested) or "\x00" in str(requested):
        raise PathNotAllowed(f"{what} must be a non-empty path string", detail={"what": what})
    base = Path(root).resolve()
    path = Path(requested)
    resolved = (path if path.is_absolute() else base / path).resolve()
    inside = resolved.is_relative_to(base) and (allow_root or resolved != base)
    if not inside:
        where = "at or inside" if allow_root else "inside"
        raise PathNotAllowed(f"{what} {str(requested)[:200]!r} is not {where} {base} (this orchestrator's "
                             f"configured folder; start it with another one to use another)",
                             detail={"what": what, "path": str(resolved)[:300], "root": str(base)})
    return resolved
