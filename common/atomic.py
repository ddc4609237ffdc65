"""Atomic file writes: the one helper every writer of durable files uses.

A reader (or a process restarted after a crash or a power cut) sees the old file or the new one, never
half of one, and a written file survives a power cut once the call returns:

1. the data goes to a *unique* temporary name in the same folder (``mkstemp``: two writers of one file, or
   two orchestrators, never share a temporary file);
2. the temporary file is fsynced;
3. it is renamed over the target (atomic on POSIX);
4. the folder is fsynced, so the rename itself is durable.

Any failure (disk full: ``ENOSPC``) removes the temporary file and raises ``OSError`` to the caller: nothing
is swallowed, and the old file, if any, is untouched.

A writer that commits a whole folder at once (the model library stages an entry's files, then renames the
folder) writes its files in place instead, with ``write_synced`` / ``fsync_file``, and fsyncs the folders
with ``fsync_dir``: the rename is its commit point. ``sha256_file`` is the digest such writers record and
readers check.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path


def fsync_dir(path: Path) -> None:
    """fsync a folder so that a rename or a new entry in it is on disk."""
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_file(path: Path | str) -> None:
    """fsync a file already written and closed (by a writer that only takes a path: Open3D, numpy)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_synced(path: Path | str, data: bytes) -> None:
    """Write ``data`` to ``path`` in place and fsync it: for files inside a folder committed by a rename."""
    with open(path, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())


def sha256_file(path: Path | str) -> str:
    """Hex SHA-256 of a file's bytes, read in 1 MiB chunks (models are tens of MB)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: Path | str) -> Iterator[Path]:
    """Yield a unique temporary path beside ``path``; on a clean exit it is fsynced and renamed over ``path``.

    For writers that need a file name (Open3D, numpy): write the temporary path inside the ``with`` block.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}")
    os.close(fd)
    try:
        yield Path(tmp)
        fsync_file(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; session folders and libraries are shared
        os.replace(tmp, path)
        fsync_dir(path.parent)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: Path | str, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically and durably (see the module doc)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(data)


def atomic_write_with(path: Path | str, write: Callable[[Path], object]) -> None:
    """``write(tmp_path)`` then publish it at ``path`` atomically; ``write`` returning ``False`` is a failure."""
    with atomic_path(path) as tmp:
        if write(tmp) is False:
            raise OSError(f"could not write {path}")
