"""Which objects the twin's service may load when a request names one: only from its configured roots.

A ``sim/world`` ``reset`` names its object. Resolved as given, any path on the machine was tried, and the
answers told a requester what exists (``/etc`` -> "no mesh in folder /etc", ``/nonexistent`` -> "unknown
object"): an existence oracle over the whole filesystem. The service now loads an object only from

- the demo objects that ship with objscan (``demo_objects.py``), by name or by path inside their folder;
- the HOPE folder (``catalogue.hope_root()``), by name or by path inside it;
- object folders configured at start (``--object-dir``, repeatable, and ``$OBJSCAN_SIM_OBJECT_DIRS``,
  separated by ``os.pathsep``), by path inside them or by the name of a sub-folder or mesh file in them;
- the mesh file or folder given at start (``--object PATH``);
- the object its world already holds (the running session's, or the one restored from its state file);
- the built-in ``charuco`` board.

Anything else gets ONE answer, ``object_not_found`` with the same message whether the path is outside the
roots or absent inside them; paths are compared after resolving symlinks and ``..`` without asking the
filesystem what a path outside the roots holds. The library function ``catalogue.load_object`` keeps
loading any path: it serves the local CLI and benchmarks, which already have the user's own rights.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from services.sim.catalogue import (
    CHARUCO_OBJECT,
    ENV_OBJECT_DIRS,
    hope_names,
    hope_root,
    how_to_name_objects,
    named_in_folder,
    resolve_object,
)
from services.sim.demo_files import OBJECTS_DIR
from services.sim.demo_objects import demo_folder, demo_names
from services.sim.errors import SimObjectError


def _real(path: str | Path) -> Path:
    """``path`` with ``~``, ``..`` and symlinks resolved (``realpath`` never raises on a missing path)."""
    return Path(os.path.realpath(os.path.expanduser(str(path))))


def _is_bare_name(text: str) -> bool:
    """A name, not a path: one component, no separator, not ``.``/``..``."""
    return bool(text) and os.sep not in text and (os.altsep is None or os.altsep not in text) \
        and text not in (".", "..")


@dataclass(frozen=True)
class ObjectRoots:
    """The folders and files a request may name objects from; ``check`` is the one gate."""

    folders: tuple[Path, ...]
    files: tuple[Path, ...] = ()

    @classmethod
    def configured(cls, start_object: str | None = None, object_dirs: Iterable[str] = (),
                   env: dict[str, str] | None = None) -> ObjectRoots:
        """The demo objects' and HOPE folders, ``object_dirs``, ``$OBJSCAN_SIM_OBJECT_DIRS`` and the start
        object when it is a path."""
        environ = os.environ if env is None else env
        dirs = [OBJECTS_DIR, hope_root(), *object_dirs]
        dirs += [d for d in environ.get(ENV_OBJECT_DIRS, "").split(os.pathsep) if d.strip()]
        files: list[Path] = []
        if start_object and not _is_bare_name(start_object.strip()):
            start = _real(start_object.strip())
            (dirs if start.is_dir() else files).append(start)
        return cls(folders=tuple(_real(d) for d in dirs), files=tuple(files))

    def allows(self, path: Path) -> bool:
        """Whether a resolved path is one of the files or inside one of the folders (pure path arithmetic)."""
        return path in self.files or any(path == f or path.is_relative_to(f) for f in self.folders)

    def not_found(self, text: str) -> SimObjectError:
        """The one answer for "not allowed" and "not there": nothing in it depends on the filesystem."""
        known = hope_names()
        return SimObjectError(f"unknown object {text[:200]!r}: not an object name nor a mesh in the twin's object "
                              f"folders (--object-dir, ${ENV_OBJECT_DIRS}) ({how_to_name_objects(known)})",
                              code="object_not_found", detail={"name": text[:200], "demo": demo_names(),
                                                               "known": known})

    def _by_name(self, text: str) -> str:
        """What a bare name loads as: itself for a demo object or a HOPE name, else the path of the sub-folder
        or mesh file of that name in the first object folder holding one (never anything in the service's
        working directory)."""
        if demo_folder(text) is not None:
            return text
        for folder in (hope_root(), *self.folders):
            found = named_in_folder(folder, text)
            if found is not None and self.allows(_real(found)):
                return text if folder == hope_root() else str(found)
        raise self.not_found(text)

    def check(self, name: str, current: tuple[str, str | None] | None = None) -> str:
        """What the service may load for ``name`` (stripped; a bare name found in an object folder becomes its
        path), else the ``not_found`` error.

        ``current``: (name, source path) of the object the world holds; naming it again is always allowed.
        A bare name is a demo object, a HOPE name or an object in one of the object folders, never a folder
        of the service's working directory.
        """
        text = str(name).strip() if isinstance(name, str) else ""
        if not text or "\x00" in text:
            raise self.not_found(text)
        if text == CHARUCO_OBJECT or (current is not None and text in current):
            return text
        requested = text
        if _is_bare_name(text):
            text = self._by_name(text)
        elif not self.allows(_real(text)):
            raise self.not_found(text)
        try:
            resolve_object(text)
        except SimObjectError as exc:
            if exc.code == "object_not_found":  # absent inside a root: the same answer as outside them
                raise self.not_found(requested) from None
            raise
        return text


def start_args(object_name: str) -> list[str]:
    """The sim's start flags that let a cell started for ``object_name`` load it: ``--object PATH`` when it names
    a mesh file or folder (a demo object or a HOPE name needs none). A command that starts its own twin and
    then asks it to load a user's mesh passes these, as the operator's explicit choice."""
    text = str(object_name).strip()
    if _is_bare_name(text):
        return []
    path = Path(text).expanduser()
    return ["--object", str(path.resolve())] if path.exists() else []
