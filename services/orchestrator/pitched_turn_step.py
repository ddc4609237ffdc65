"""The state machine's side of the turn by a pitched pick (geometry: ``pitched_turn.py``): when to try it,
which chains first, and executing the first one the arm can run whole. Functions over an ``Acquisition``
(``machine.py``), so that the machine only calls in once, in a turn step's last strategies.

When: top-down grasps were planned and not one of their turns (nor a reposition) was executable where the
object stands, the plan has pitched picks (a box thin along the line from the base), and no pitched turn was
made at this view yet (one whose grasp failed on contact does not count: the next re-scan's plan tries the
other picks first). Before a lay-down, which restarts the views: this keeps them.

Which first, nearest carry first: the quarter turn, which stands the box with its thin side across the
line from the base, where frontal and top-down grasps close across it and turn it (measured with the arm's
kinematics, the 5.4 x 15.8 x 15.3 cm slab at 0.425 m: frontal and top-down turns executable with its thin
side across the line from the base or 60 degrees off it, only one top-down pose 30 degrees off it, none
along it); it is recorded as a reposition with a turn (the view is scanned again where it stands, its
commanded turn grown by the quarter turn when views before it are kept, ``TurnJournal.record_reposition``).
Then the view's own turn (``direction`` times the session's turn, the session's direction first: recorded as
any turn with a relocated set-down). Within each, the way up leaning away from the base first (a
straight-down hand reaches only 15 cm high at 0.40 m: it cannot leave a 15 cm box straight up).

A slab turned 30 degrees a view comes back thin along the line from the base every 180 degrees: the same
move stands it across again there (at a view after 0 the quarter turn leaves the views' angles uneven: two
or three of them are seen twice and as many not at all, which the session's turns say).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from common.api import ViewResult
from services.grasp.pitch import pitched
from services.orchestrator.config import RelocationConfig
from services.orchestrator.pitched_turn import LEANS_DEG, QUARTER_DEG, PitchedTurnPoses, pitched_turn_sequences

if TYPE_CHECKING:
    from services.orchestrator.states import State

#: The running acquisition (``machine.Acquisition``), typed loosely: that module imports this one.
Acquisition = Any
#: m from the base where the box is stood upright. Measured with the arm's kinematics and the scan-pose
#: check, for the 15.3 cm slab: a straight-down hand sets it down at 0.40 and 0.425 m (it reaches only
#: 15 cm high at 0.40 m, 11 cm at 0.45 m, nothing at 0.50 m), and its scan poses are reachable from 0.425 m
#: out (at 0.40 m they are not, for any object above about 12 cm).
STAND_RADIUS = 0.425


def turn_angles(turn_deg: float, fixed: int | None) -> list[float]:
    """The turns to try, in order: the quarter turn both ways (the session's direction first), then the
    view's turn (the session's direction only, once it has one; else both ways)."""
    own = [turn_deg * d for d in ((fixed,) if fixed else (1, -1))]
    quarter = [QUARTER_DEG, -QUARTER_DEG] if (fixed or 1) > 0 else [-QUARTER_DEG, QUARTER_DEG]
    return [*quarter, *own]


def stand_shifts(center: np.ndarray, config: RelocationConfig) -> list[np.ndarray]:
    """Carries (x, y, 0) to the spots the box is stood upright at, nearest first: ``STAND_RADIUS`` from the
    base at the relocation azimuths, then where it stands (only an object already there is stood up there)."""
    c = np.asarray(center, float)[:2]
    out = [np.array([*(STAND_RADIUS * np.array([np.cos(np.radians(a)), np.sin(np.radians(a))]) - c), 0.0])
           for a in config.azimuths_deg]
    out = sorted((d for d in out if np.linalg.norm(d) >= config.min_shift), key=lambda d: float(np.linalg.norm(d)))
    return [*out, np.zeros(3)]


def _pick(name: str) -> str:
    """The pick of a chain's name: its pitched pose and pads (``grasp_pitch35_rolled``)."""
    return name.split("_turn")[0]


def chains(acq: Acquisition, view: ViewResult) -> list[tuple[int, PitchedTurnPoses]]:
    """(grasp index, chain) of every pitched pick of the current plan, in the order to try them."""
    plan = acq._plan
    if plan is None:
        return []
    cfg = acq.config
    angles = turn_angles(float(cfg.turn_deg), acq.j.turn_direction)
    out: list[tuple[tuple, int, PitchedTurnPoses]] = []
    for di, d in enumerate(stand_shifts(view.center, cfg.turn.relocation)):
        for gi, grasp in enumerate(plan.grasps):
            if not any(pitched(n) for n in grasp.poses):
                continue
            for seq in pitched_turn_sequences(grasp, view.cloud.xyz, view.center, view.height, cfg.turn, [d],
                                              tuple(angles), LEANS_DEG, float(cfg.turn_deg)):
                out.append(((di, angles.index(seq.turn_deg), LEANS_DEG.index(seq.lean_deg), gi), gi, seq))
    out.sort(key=lambda c: c[0])  # stable: within a key, the generator's order (pitch, pads, carry first)
    return [(gi, seq) for _, gi, seq in out]


async def try_pitched_turn(acq: Acquisition, k: int, view: ViewResult, box: tuple[np.ndarray, np.ndarray],
                           failures: list[str]) -> State | None:
    """Turn the object of view ``k`` by a pitched pick if a chain of it is executable: the next state, or
    None when none was (or the plan has no pitched pick)."""
    if any(e.get("strategy") == "pitched turn" and not e.get("slipped") for e in acq._regrasps_now(k)):
        return None  # once a view: stood again where it could not be turned, it would only be turned back
    todo = chains(acq, view)
    if not todo:
        return None
    failed = {_pick(s.split(":")[-1]) for s in acq.j.failed_grasps.get(str(k), [])}
    todo.sort(key=lambda c: _pick(c[1].name) in failed)  # a pick that failed here: after the others
    rc = acq.config.turn.relocation
    acq.decide("turning by a pitched pick: no other turn is executable", chains=len(todo))
    scannable: dict[tuple, bool] = {}
    checks = 0
    for gi, seq in todo:
        if checks >= rc.max_checks:
            break
        spot = np.asarray(view.center, float) + seq.carry
        if not await acq._scannable_spot(spot, view.height, scannable):
            continue
        grasp = acq._plan.grasps[gi]
        checks += 1
        acq.j.counters.grasp_checks += 1
        q_start = await acq._dry_run(k, seq, view.center, float(grasp.width), failures)
        if q_start is None:
            continue
        signature = f"{grasp.kind}:{gi}:{seq.name}"
        outcome = await acq._attempt(k, gi, grasp, seq, q_start, box, signature, failures)
        if outcome is not None:  # executed, or the grasp failed (re-scanned): the journal says it was tried
            slipped = signature in acq.j.failed_grasps.get(str(k), [])
            acq.j.regrasps.setdefault(str(k), []).append(
                {"strategy": "pitched turn", "pose": seq.name, "turn_deg": seq.turn_deg,
                 "shift": np.round(seq.carry, 4).tolist(), "restart": acq.j.topple_restarts,
                 **({"slipped": True} if slipped else {})})
            return outcome
    acq.decide("no pitched turn executable", checks=checks)
    return None
