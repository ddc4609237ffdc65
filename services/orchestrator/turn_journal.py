"""The journal of the irreversible steps: a turn's intent and outcome, a reposition, a re-scan's old attempt.

A pick-turn-place and a re-scan change the world (the object turns, frames move aside) in ways a crashed
orchestrator cannot see afterwards; so each is journalled before it starts and when it ends, and a resume
settles what is open from these records. This module writes those records (into the ``Journal`` and at once
to ``journal.json``); the state machine decides when, and ``released_at`` tells a resume whether the arm
stands where an open turn would have released the object.
"""

from __future__ import annotations

import shutil
from typing import Any

import numpy as np

from common.session_folder import view_dir
from services.orchestrator.journal import Journal
from services.orchestrator.pitched_turn import QUARTER_DEG, QUARTER_TURN
from services.orchestrator.reposition import NO_TURN
from services.orchestrator.states import State
from services.session_store import SessionStore

#: how close the hand must be to an open turn's release pose for the turn to count as finished
RELEASE_TOLERANCE_M = 0.01
RELEASE_TOLERANCE_DEG = 5.0


def released_at(T_base_gripper: np.ndarray, release_T: np.ndarray) -> bool:
    """Whether the hand stands at the planned release pose (within ``RELEASE_TOLERANCE_*``)."""
    T = np.asarray(T_base_gripper, float)
    R = np.asarray(release_T, float)
    angle = np.degrees(np.arccos(np.clip((np.trace(T[:3, :3].T @ R[:3, :3]) - 1) / 2, -1.0, 1.0)))
    return float(np.linalg.norm(T[:3, 3] - R[:3, 3])) < RELEASE_TOLERANCE_M and angle < RELEASE_TOLERANCE_DEG


class TurnJournal:
    """Writes the records of the irreversible steps into one acquisition's journal and session folder."""

    def __init__(self, j: Journal, store: SessionStore, turn_deg: float):
        self.j = j
        self.store = store
        self.turn_deg = turn_deg

    def _save(self) -> None:
        self.store.save_journal(self.j.to_dict())

    def intent(self, phase: str | None, **fields: Any) -> None:
        """Write where a turn stands before the next irreversible step: ``closing`` (the gripper is about
        to close), ``holding`` (the object is held and may be lifted and turned), or ``None`` (over)."""
        if phase == "closing":
            fields = {"view": int(self.j.view), **fields}
        if phase is None:
            self.j.turn_intent = None
            self.j.holding = False
        else:
            self.j.turn_intent = {**(self.j.turn_intent or {}), **fields, "phase": phase}
            self.j.holding = phase == "holding"
        self._save()

    def record_turn(self, k: int, direction: int, shift: np.ndarray | None = None) -> None:
        """The object is released where the turn ends: the next view, its commanded turn, one journal write.
        A relocated set-down (``shift``) also gives the next view's expected centre: its scan poses are
        placed around where the object now stands, not where it stood. A pick-and-place without a turn
        (a reposition) is recorded by ``record_reposition`` instead: no view is added; so is a quarter turn
        (``pitched_turn.QUARTER_TURN``), with its turn."""
        if direction == NO_TURN:
            self.record_reposition(k, shift)
            return
        if abs(direction) == QUARTER_TURN:
            self.record_reposition(k, shift, turn_deg=QUARTER_DEG * (1 if direction > 0 else -1))
            return
        j = self.j
        if shift is not None and str(k) in j.centers:
            c = np.asarray(j.centers[str(k)], float)
            j.centers[str(k + 1)] = (c + np.asarray(shift, float)).tolist()
            j.heights[str(k + 1)] = j.heights[str(k)]
        j.turns_deg.append(j.turns_deg[k] + direction * self.turn_deg)
        if j.turn_direction is None:
            j.turn_direction = direction
        j.view = k + 1
        j.grasp_mode = "auto"
        j.state = State.SCAN.value
        j.turn_intent = None
        j.holding = False
        self._save()

    def record_reposition(self, k: int, shift: np.ndarray | None, turn_deg: float = 0.0,
                          strategy: str | None = None, aside: str | None = None) -> None:
        """The object was set down at another spot: view ``k`` is scanned again where the object now stands
        (its old frames are moved aside, never deleted). Unturned, it keeps its commanded turn. Turned by
        ``turn_deg`` (a quarter turn, or a push's measured turn: ``strategy`` "push", its frames set aside as
        ``aside``), view ``k``'s commanded turn grows by it when views before it are kept (the registration's
        turn prior is the turn made); at view 0 nothing is kept yet, and the view scanned again is where the
        object's frame (turn 0) starts."""
        j = self.j
        d = np.zeros(3) if shift is None else np.asarray(shift, float)
        if str(k) in j.centers:
            j.centers[str(k)] = (np.asarray(j.centers[str(k)], float) + d).tolist()
            if k == 0:  # view 0's scan poses are placed around the located object: it now stands here
                j.centers["-1"] = list(j.centers["0"])
        strategy = strategy or ("quarter turn" if turn_deg else "reposition")
        n = 1 + sum(1 for e in j.regrasps.get(str(k), []) if e.get("strategy") == strategy)  # folder name
        if turn_deg and k > 0:
            j.turns_deg[k] = float(j.turns_deg[k]) + float(turn_deg)
        j.regrasps.setdefault(str(k), []).append(
            {"strategy": strategy, "restart": j.topple_restarts, "shift": np.round(d, 4).tolist(),
             "to": np.round(np.asarray(j.centers.get(str(k), d), float)[:2], 4).tolist(),
             **({"turn_deg": float(turn_deg), "commanded_turn_deg": float(j.turns_deg[k])} if turn_deg else {})})
        if strategy == "quarter turn":
            j.counters.regrasps += 1
        elif strategy == "reposition":
            j.counters.repositions += 1
        j.grasp_mode = "auto"
        j.turn_intent = None
        j.holding = False
        aside = aside or f"{'quarter' if turn_deg else 'moved'}{n}"
        j.pending_rescan = {"view": k, "attempt": n, "aside": aside}
        self._save()
        self.finish_rescan()
        j.state = State.SCAN.value
        self._save()

    def begin_rescan(self, k: int, attempt: int) -> None:
        """The intent of re-scan ``attempt`` of view ``k``, written before the old attempt moves aside: a
        kill between the move and the next journal write must not lose the view's frames."""
        self.j.pending_rescan = {"view": k, "attempt": attempt}
        self.j.scan_sets.pop(str(k), None)
        self._save()
        self.finish_rescan()

    def finish_rescan(self) -> None:
        """Move the view's old attempt aside (idempotent: a resume calls it again) and clear the intent."""
        j = self.j
        pending = j.pending_rescan
        k, n = int(pending["view"]), int(pending["attempt"])
        src = view_dir(self.store.path, k)
        dst = src.with_name(f"{src.name}_{pending.get('aside') or f'attempt{n}'}")
        if src.exists() and not dst.exists():  # keep every captured frame: the old attempt moves aside
            shutil.move(str(src), str(dst))
        j.pending_rescan = None
        j.view = k
        j.scan_sets.pop(str(k), None)
