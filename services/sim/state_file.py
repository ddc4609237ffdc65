"""The twin's world on disk, so a killed and restarted twin carries on with the same world.

The sim service is the world of a simulated cell: where the object stands (after every turn), whether the
gripper holds it, where the arm is, which draws of the error profile come next. A twin that comes back
empty after a crash would render a different scene than the one the orchestrator has been scanning. So
the service writes ``World.snapshot()`` (plus its own frame counter) to one JSON file after every change,
atomically (temporary file, fsync, rename: a reader sees the old or the new state, never half of one), and
loads it when it starts.

Where the file is (first that applies):

1. ``--state-file PATH`` (``--state-file none`` turns persistence off);
2. ``$OBJSCAN_SIM_STATE_FILE``;
3. ``$OBJSCAN_STATE_DIR`` (default ``$XDG_STATE_HOME/objscan``, i.e. ``~/.local/state/objscan``) /
   ``sim-{robot}-{network}.json``, where ``network`` is a short hash of the Zenoh endpoints the service
   connects to and listens on: two cells on one machine (two test runs, two simulated robots on
   different routers) never share a world, a restarted twin of the same cell finds its own.

Lifetime: a clean stop (SIGTERM, SIGINT, Ctrl-C, ``docker compose stop``) ends the world and removes the
file, so the next start is fresh, as before. Only a twin that dies (killed, crashed, OOM, power loss)
leaves the file behind for its restart. To start fresh anyway: ``--fresh`` (ignores and overwrites the
file), or delete the file; the orchestrator also resets the world at every acquisition's start.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from pathlib import Path
from typing import Any

from common.log import event
from common.session_folder import atomic_write_bytes, json_default
from services.sim.world import SimStateError

log = logging.getLogger("objscan.sim")

#: Version of the file's outer layout (the world inside carries its own ``format``).
FILE_FORMAT = "objscan-sim-state/1"
DISABLED = ("", "none", "off", "-")


def default_state_dir() -> Path:
    """``$OBJSCAN_STATE_DIR``, else ``$XDG_STATE_HOME/objscan``, else ``~/.local/state/objscan``."""
    if os.environ.get("OBJSCAN_STATE_DIR"):
        return Path(os.environ["OBJSCAN_STATE_DIR"]).expanduser()
    xdg = os.environ.get("XDG_STATE_HOME")
    return (Path(xdg).expanduser() if xdg else Path.home() / ".local" / "state") / "objscan"


def network_key(connect: list[str], listen: list[str]) -> str:
    """A short, stable name for the Zenoh network a service is on (``local`` when it names none)."""
    ends = sorted(connect) + ["|"] + sorted(listen)
    if not connect and not listen:
        return "local"
    return hashlib.sha1("\n".join(ends).encode()).hexdigest()[:10]


def resolve_state_path(option: str | None, robot: str, connect: list[str], listen: list[str]) -> Path | None:
    """Where this twin keeps its world (module docstring), or None when persistence is off."""
    explicit = option if option is not None else os.environ.get("OBJSCAN_SIM_STATE_FILE")
    if explicit is not None:
        return None if explicit.strip().lower() in DISABLED else Path(explicit).expanduser()
    safe_robot = "".join(c if c.isalnum() or c in "-_." else "_" for c in robot) or "robot"
    return default_state_dir() / f"sim-{safe_robot}-{network_key(connect, listen)}.json"


class StateFile:
    """One twin's state file: ``save`` (atomic), ``load`` (None when absent), ``discard``."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.saves = 0

    def save(self, world_snapshot: dict[str, Any], **extra: Any) -> None:
        """Write the world (and the service's ``extra`` fields, e.g. its frame counter) atomically."""
        doc = {"format": FILE_FORMAT, "saved_at": time.time(), **extra, "world": world_snapshot}
        atomic_write_bytes(self.path, json.dumps(doc, default=json_default).encode())
        self.saves += 1

    def load(self) -> dict[str, Any] | None:
        """The saved document, or None when there is no file. A file that is there but unusable raises
        ``SimStateError`` (``bad_snapshot``): starting fresh silently would render a different world than
        the one the cell was scanning, so the operator decides (``--fresh`` or delete the file)."""
        try:
            raw = self.path.read_bytes()
        except FileNotFoundError:
            return None
        except OSError as exc:
            raise SimStateError(f"cannot read the twin's state file {self.path}: {exc}", code="bad_snapshot",
                                detail={"path": str(self.path)}) from None
        try:
            doc = json.loads(raw)
        except ValueError as exc:
            raise SimStateError(f"the twin's state file {self.path} is not JSON ({exc}); start with --fresh or "
                                "delete it", code="bad_snapshot", detail={"path": str(self.path)}) from None
        if not isinstance(doc, dict) or doc.get("format") != FILE_FORMAT or not isinstance(doc.get("world"), dict):
            got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
            raise SimStateError(f"the twin's state file {self.path} has format {got!r}, expected {FILE_FORMAT!r}; "
                                "start with --fresh or delete it", code="bad_snapshot",
                                detail={"path": str(self.path)})
        return doc

    def discard(self) -> None:
        """Remove the file (a clean stop: the world ends with the twin)."""
        try:
            self.path.unlink()
        except FileNotFoundError:
            pass
        except OSError as exc:
            event(log, "could not remove the state file", logging.WARNING, path=str(self.path), error=str(exc))
