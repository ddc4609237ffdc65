"""The acquisition journal as a typed record: what ``journal.json`` holds, field by field.

The state machine used to keep its journal in a plain dict grown with ``setdefault``; a misspelt key then
silently started a new entry. ``Journal`` names every field once with its type and default. Its JSON form
(``to_dict``) is the one the old code wrote, key for key, so readers of ``journal.json`` (report, library,
recording replay, tests) are unchanged, and ``from_dict`` reads journals written by the old code: a key it
lacks takes its default, a key it does not know is kept in ``extra`` and written back (never dropped).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Any

#: Version 1: the dict journal of the first releases; version 2: this record (same keys, always all present).
JOURNAL_VERSION = 2


@dataclass
class Counters:
    """Totals over the whole session (the report's ``counters``)."""

    captures: int = 0
    grasp_attempts: int = 0  # executed pick-turn-places
    grasp_checks: int = 0  # dry-run checks of one (grasp, offset, direction)
    slips: int = 0  # executed grasps that did not hold
    rescans: int = 0
    topple_restarts: int = 0
    regrasps: int = 0  # regrasp strategies executed (services/orchestrator/regrasp.py)
    repositions: int = 0  # pick-and-places without a turn back to a favoured spot (reposition.py)
    lay_downs: int = 0  # tall objects laid on their side to be scanned lying (lay_down.py)
    pushes: int = 0  # objects no pick reached, turned on the table by a push (push.py)

    def to_dict(self) -> dict[str, int]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any] | None) -> Counters:
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: int(v) for k, v in (data or {}).items() if k in names})


@dataclass
class Journal:
    """Where an acquisition stands and why it went the way it did; rewritten atomically after every step."""

    config: dict[str, Any]
    state: str = "locate"
    view: int = 0
    status: str = "running"  # running | done | failed | stopped
    turns_deg: list[float] = field(default_factory=lambda: [0.0])  # cumulative commanded turn per view
    centers: dict[str, list[float]] = field(default_factory=dict)  # view -> object footprint centre (-1: locate)
    heights: dict[str, float] = field(default_factory=dict)  # view -> object height
    rescans: dict[str, int] = field(default_factory=dict)  # view -> re-scans so far
    grasp_mode: str = "auto"  # auto | top_down
    scan_sets: dict[str, list[list[list[float]]]] = field(default_factory=dict)  # view -> chosen scan poses
    decisions: list[dict[str, Any]] = field(default_factory=list)
    timings_s: dict[str, float] = field(default_factory=dict)  # state -> seconds spent in it
    counters: Counters = field(default_factory=Counters)
    started: float = field(default_factory=time.time)
    simulated: bool | None = None  # None until the cell was prepared
    error: dict[str, Any] | None = None
    previous_errors: list[dict[str, Any]] = field(default_factory=list)
    stopped_in: str | None = None  # the state an e-stop interrupted
    pending_rescan: dict[str, Any] | None = None  # a re-scan whose old attempt is being moved aside
    turn_intent: dict[str, Any] | None = None  # an open pick-turn-place (phase closing | holding)
    holding: bool = False
    turn_direction: int | None = None  # +1 / -1 once the session has turned one way
    failed_grasps: dict[str, list[str]] = field(default_factory=dict)  # view -> signatures that did not hold
    limits: dict[str, dict[str, Any]] = field(default_factory=dict)  # view -> planner/dry_run/grasp evidence
    topple_restarts: int = 0
    regrasps: dict[str, list[dict[str, Any]]] = field(default_factory=dict)  # view -> regrasp strategies tried
    laid_down: dict[str, Any] | None = None  # the object was laid on its side: where, how, from which view
    pushes: list[dict[str, Any]] = field(default_factory=list)  # pushes executed: which, from which view
    model_path: str | None = None
    model_ready_s_after_last_view: float | None = None
    accuracy: dict[str, float] | None = None
    model_accepted: bool | None = None  # the dynamic stage's verdict on the model (None until built)
    model_why: str = ""  # the acceptance criteria an unaccepted model misses
    library_entry: Any = None
    version: int = JOURNAL_VERSION  # always the current one once loaded: it is written in the new form
    extra: dict[str, Any] = field(default_factory=dict)  # keys a newer or older writer added: kept, not used

    def limits_of(self, view: int) -> dict[str, Any]:
        """The evidence of what stood in the way at ``view`` (created empty on first use)."""
        return self.limits.setdefault(str(view), {})

    def update(self, **fields: Any) -> None:
        """Set several fields at once; an unknown name is an error (the point of a typed journal)."""
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(fields) - names)
        if unknown:
            raise AttributeError(f"the journal has no field(s) {unknown}")
        for k, v in fields.items():
            setattr(self, k, v)

    def to_dict(self) -> dict[str, Any]:
        """The JSON form written to ``journal.json`` (the old dict's keys; ``extra`` merged back in)."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "extra"}
        out["counters"] = self.counters.to_dict()
        return {**self.extra, **out}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Journal:
        """A journal from ``journal.json``, old (version 1, keys added as the run went) or new."""
        names = {f.name for f in dataclasses.fields(cls)} - {"extra", "counters"}
        known = {k: v for k, v in data.items() if k in names}
        extra = {k: v for k, v in data.items() if k not in names and k not in ("counters", "extra", "updated")}
        known = {k: v for k, v in known.items() if v is not None or k in _NULLABLE}
        j = cls(**{"config": data.get("config") or {}, **known}, counters=Counters.from_dict(data.get("counters")),
                extra={**(data.get("extra") or {}), **extra})
        j.view = int(j.view)
        j.version = JOURNAL_VERSION
        j.topple_restarts = int(j.topple_restarts or 0)
        return j


_NULLABLE = frozenset(f.name for f in dataclasses.fields(Journal)
                      if f.default is None and f.default_factory is dataclasses.MISSING)
