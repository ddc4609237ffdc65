"""The state machine's side of a push (geometry: ``push.py``): when to push, checking and running one, and
restarting the views afterwards. Functions over an ``Acquisition`` (``machine.py``), which calls in at
one point: the last strategy of a turn step.

When: the view's re-scans are used up (the next failure ends the run), no grasp turned the object, no
reposition, pitched turn or lay-down was executable, the object stands (a lying one is picked top-down),
and fewer than ``AcquisitionConfig.max_pushes`` pushes were made. It replaces a certain stop, never a turn.

How: the whole push is dry-run first (over the start, down, round the arc, back and up); then the hand
closes above the start, runs it, and opens again above the object.

After: what the push achieved is not assumed. After view 0, view ``k`` is scanned again where the push
aims the object, under a provisional turn (half the arc); once registered, the push's turn is measured from
its footprint's long side against the view before the push (``push.measured_turn_deg``, ``measure_push``)
and becomes view ``k``'s commanded turn grown by it: the push is a turn, the views before it kept (a tall box
whose only grasp is tied to its yaw needs a push each time the wrist's reach runs out, two or three in twelve
views). Where the turn cannot be told (a footprint near square before or after, a turn no push gives), or at
view 0, the views so far are set aside (``view_KK_pushedN``, kept on disk, never fused with later ones) and
the views restart at 0 where the object now stands, its expected centre the one the push aims at, with a
fresh re-scan budget.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from common.api import ViewResult
from common.errors import RemoteError
from services.orchestrator.limits import ARM_UNAVAILABLE_CODES
from services.orchestrator.motion import FULL_OPENING
from services.orchestrator.push import ARC_DEG, PushPoses, long_side_deg, measured_turn_deg, push_sequences
from services.orchestrator.views_aside import restart_views

if TYPE_CHECKING:
    from services.orchestrator.states import State

#: Degrees of turn a push is recorded with until the view after it is measured: about what it gives (half the arc).
PROVISIONAL_DEG = 0.5 * ARC_DEG
#: The running acquisition (``machine.Acquisition``), typed loosely: that module imports this one.
Acquisition = Any


def wanted(acq: Acquisition, k: int, view: ViewResult) -> bool:
    """Whether a push is the next strategy at view ``k`` (see the module's "When")."""
    if len(acq.j.pushes) >= acq.config.max_pushes or acq._lying(view.cloud.xyz, view.height):
        return False
    return int(acq.j.rescans.get(str(k), 0)) >= acq.config.max_rescans


def _preferred_sense(acq: Acquisition, k: int) -> int | None:
    """The sense a push should turn the object in: after view 0 the way the views turn it (a push the other
    way turns it back to where views were taken), at view 0 the way the last push did."""
    if k > 0 and acq.j.turn_direction:
        return 1 if acq.j.turn_direction > 0 else -1
    return int(acq.j.pushes[-1]["sense"]) if acq.j.pushes else None


def _moves(seq: PushPoses) -> list[tuple[np.ndarray, bool]]:
    """The straight moves after the one over the start, each with whether it may touch the object."""
    return [(seq.start, False), *((T, True) for T in seq.arc), *((T, True) for T in seq.retreat)]


async def check_push(acq: Acquisition, seq: PushPoses) -> np.ndarray:
    """Dry-run one push whole from the arm's current joints; its joints over the start, or raises. The object's
    box is not among the obstacles (the caller clears it): the fingers go where the object stands, which is
    the point of a push, and it moves ahead of them; the table and the arm's envelope are checked."""
    m = acq.config.turn
    state = await acq.cell.state()
    q = (await acq.cell.move("pose", target=seq.above, q=np.asarray(state.position, float), speed=m.speed_scale,
                             dry_run=True)).q
    q_above = np.asarray(q, float)
    for T, contact in _moves(seq):
        q = (await acq.cell.move("linear", target=T, q=q, speed=m.approach_speed_scale, contact=contact,
                                 dry_run=True, check_opening=0.0)).q
    return q_above


async def try_push(acq: Acquisition, k: int, view: ViewResult, box: tuple[np.ndarray, np.ndarray],
                   failures: list[str]) -> State | None:
    """Turn the object of view ``k`` by a push if one is executable: the next state, or None when none was
    (or a push is not the next strategy here). ``box``: the object's box, set again when no push ran."""
    if not wanted(acq, k, view):
        return None
    m = acq.config.turn
    seqs = push_sequences(view.cloud.xyz, view.height, m.clearance, sense=_preferred_sense(acq, k))
    acq.decide("pushing the object round: no pick reaches it", pushes=[s.name for s in seqs])
    await acq.motion.escape(view.center, view.height)
    await acq.cell.clear_object_box()
    for seq in seqs:
        acq.j.counters.grasp_checks += 1
        try:
            q_above = await check_push(acq, seq)
        except RemoteError as exc:
            if exc.code in ARM_UNAVAILABLE_CODES:
                raise
            failures.append(f"{seq.name}:{exc.code}")
            acq._limits(k).setdefault("dry_run", []).append(exc.code)
            acq.decide("push not executable", push=seq.name, code=exc.code, message=exc.message[:200])
            continue
        await _execute(acq, seq, q_above)
        before = long_side_deg(view.cloud.xyz[:, :2]) if k > 0 else None
        if before is not None:
            return _continue_views(acq, k, seq, view, before)
        return _restart_views(acq, k, seq, view)
    acq.decide("no push executable", checks=len(seqs))
    await acq.cell.set_object_box(*box)
    return None


async def _execute(acq: Acquisition, seq: PushPoses, q_above: np.ndarray) -> None:
    """Run a checked push: closed over the start, down, round the arc, back, up, open."""
    m, c = acq.config.turn, acq.cell
    await acq.motion.transit_joints(q_above, m.speed_scale)
    await c.gripper(0.0, m.gripper_force)
    for T, contact in _moves(seq):
        await c.move("linear", target=T, speed=m.approach_speed_scale, contact=contact)
    await c.gripper(FULL_OPENING, m.gripper_force)


def _record(seq: PushPoses, k: int, view: ViewResult) -> dict:
    """The journal's record of push ``seq`` made at view ``k``: which, its sense, from where, to where expected."""
    return {"push": seq.name, "from_view": k, "sense": seq.sense,
            "from_center": np.asarray(view.center, float).tolist(),
            "expected_center": [float(x) for x in seq.expected_center]}


def _continue_views(acq: Acquisition, k: int, seq: PushPoses, view: ViewResult, before_deg: float) -> State:
    """The object was pushed at view ``k``: view ``k`` is scanned again where the push aims it, under the
    provisional turn (``TurnJournal.record_reposition``); ``measure_push`` replaces it by the measured one."""
    from services.orchestrator.states import State

    j = acq.j
    n = len(j.pushes) + 1
    provisional = seq.sense * PROVISIONAL_DEG
    shift = np.array([*(np.asarray(seq.expected_center, float)[:2] - np.asarray(view.center, float)[:2]), 0.0])
    j.pushes.append({**_record(seq, k, view), "turn_deg": None, "measured": None, "provisional_turn_deg": provisional,
                     "long_side_before_deg": round(before_deg, 3)})
    j.counters.pushes += 1
    j.rescans[str(k)] = 0  # a new situation: the view's re-scan budget starts again (pushes are bounded)
    acq._plan = None
    acq.decide("pushed round: view scanned again where the object now stands, its turn to be measured",
               push=seq.name, view=k)
    acq.turns.record_reposition(k, shift, turn_deg=provisional, strategy="push", aside=f"pushed{n}")
    return State.SCAN


def measure_push(acq: Acquisition, k: int, result: ViewResult) -> State | None:
    """View ``k`` registered where a push left the object: its commanded turn made the measured one (None: go
    on with the view), or, where the turn cannot be told, the views restart from the object as it stands (the
    next state)."""
    from services.orchestrator.states import State

    j = acq.j
    push = j.pushes[-1] if j.pushes else None
    if push is None or push.get("from_view") != k or "measured" not in push or push["measured"] is not None:
        return None
    after = long_side_deg(result.cloud.xyz[:, :2])
    turned = None if after is None else measured_turn_deg(float(push["long_side_before_deg"]), after,
                                                          int(push["sense"]))
    if turned is None:
        push["measured"] = False
        acq.decide("the push's turn cannot be told from the object's footprint: the views restart here",
                   view=k, long_side_deg=None if after is None else round(after, 1))
        center = np.asarray(result.center, float).tolist()
        restart_views(acq.store.path, j, k, f"pushed{len(j.pushes)}_untold", center, float(result.height))
        acq.store.save_journal(j.to_dict())
        return State.SCAN
    j.turns_deg[k] = float(j.turns_deg[k]) - float(push["provisional_turn_deg"]) + turned
    push.update(turn_deg=round(turned, 2), measured=True)
    entry = next((e for e in reversed(j.regrasps.get(str(k), [])) if e.get("strategy") == "push"), None)
    if entry is not None:
        entry.update(turn_deg=round(turned, 2), commanded_turn_deg=float(j.turns_deg[k]))
    acq.decide("push measured: the view's commanded turn is the push's", view=k, turn_deg=round(turned, 1),
               commanded_turn_deg=round(float(j.turns_deg[k]), 1))
    acq.store.save_journal(j.to_dict())
    return None


def _restart_views(acq: Acquisition, k: int, seq: PushPoses, view: ViewResult) -> State:
    """The object was pushed at view ``k``: views 0..k set aside, the views restart at 0 where it is expected."""
    from services.orchestrator.states import State

    j = acq.j
    n = len(j.pushes) + 1
    center = [float(x) for x in seq.expected_center]
    restart_views(acq.store.path, j, k, f"pushed{n}", center, view.height)
    j.pushes.append(_record(seq, k, view))
    j.counters.pushes += 1
    acq._plan = None
    acq.decide("pushed round: the views restart where it now stands (the earlier views are kept aside)",
               push=seq.name, from_view=k, expected_center=center)
    acq.store.save_journal(j.to_dict())
    return State.SCAN
