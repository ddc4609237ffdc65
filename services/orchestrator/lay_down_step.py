"""The state machine's side of laying a tall object on its side (geometry: ``lay_down.py``): when to try it,
trying it, and the journal record of it. Functions over an ``Acquisition`` (``machine.py``), kept out of the
machine so that it only calls in at three points: the last strategy of a turn step, the record at the
release, and the next state after the release.

A chain that would leave the object lying no lower than it stands is not tried (a slab as wide as it is
tall, laid on its other edge, is as far out of reach lying).

When: the view's re-scans are used up (the next failure ends the run), no grasp turned the standing object
even top-down, and no reposition was executable; the object stands markedly taller than it is thin
(``lay_down.stands_tall``); it was not laid down before. It replaces a certain stop, never a turn.

After: the standing views are set aside (``view_KK_standing``, kept on disk, never fused with the lying
ones), the views restart at 0 where the object lies with a fresh re-scan budget, the journal's
``laid_down`` says where and how, and every later plan treats the object as lying (``Acquisition._lying``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from common.api import ViewResult
from services.grasp.pitch import pitched
from services.orchestrator.lay_down import (
    LayDownPoses,
    as_recorded,
    carry_shifts,
    grasps_for_lay_down,
    lay_down_sequences,
    stands_tall,
)
from services.orchestrator.planning import object_box
from services.orchestrator.views_aside import restart_views

if TYPE_CHECKING:
    from services.orchestrator.states import State

#: The running acquisition (``machine.Acquisition``), typed loosely: that module imports this one.
Acquisition = Any


def wanted(acq: Acquisition, k: int, view: ViewResult) -> bool:
    """Whether a lay-down is the next strategy at view ``k`` (see the module's "When")."""
    if (acq.j.laid_down or {}).get("state") == "done" or acq._lying(view.cloud.xyz, view.height):
        return False
    if int(acq.j.rescans.get(str(k), 0)) < acq.config.max_rescans:
        return False
    return stands_tall(view.cloud.xyz, view.height)


async def try_lay_down(acq: Acquisition, k: int, view: ViewResult, box: tuple[np.ndarray, np.ndarray],
                       failures: list[str]) -> State | None:
    """Lay the standing object of view ``k`` on its side if a chain for it is executable: the next state, or
    None when none was (or a lay-down is not the next strategy here)."""
    if not wanted(acq, k, view):
        return None
    rc = acq.config.turn.relocation
    plan = await acq.cell.plan_grasps(view.cloud, view.table, "both")
    acq.store.save_json(f"view_{k:02d}/grasps_lay_down.json", {
        "mode": "both", "explanation": plan.explanation, "rejections": plan.rejections,
        "grasps": [{"kind": g.kind, "rank": g.rank, "width": g.width, "contacts": np.asarray(g.contacts).tolist(),
                    "metrics": g.metrics} for g in plan.grasps]})
    order = grasps_for_lay_down(list(plan.grasps), view.height)
    acq.decide("laying the object on its side: no grasp turns it standing", height=round(view.height, 4),
               grasps=len(plan.grasps))
    scannable: dict[tuple, bool] = {}
    checks = [0, 0]  # dry runs of straight tips, of tips through the wrist's singularity: each its own budget
    lower_only = 0
    # per carry, pitched picks first: they lean away from the base, which the arm reaches wherever it can pick at
    # all; the tips through the wrist's singularity (joint-space chords, on the near ring) after every other
    chains = sorted(((di, gi, seq) for di, d in enumerate(carry_shifts(view.center, rc)) for gi in order
                     for seq in lay_down_sequences(plan.grasps[gi], view.cloud.xyz, view.center, view.height,
                                                   acq.config.turn, [d])),
                    key=lambda c: (bool(c[2].arcs), c[0], not pitched(c[2].name)))
    for _, gi, seq in chains:
        budget = int(bool(seq.arcs))
        if checks[budget] >= rc.max_checks:
            continue
        if seq.lying_height >= view.height:  # lying no lower than it stands: nothing gained
            lower_only += 1
            continue
        grasp = plan.grasps[gi]
        if not await acq._scannable_spot(seq.lying_center, seq.lying_height, scannable):
            continue
        checks[budget] += 1
        acq.j.counters.grasp_checks += 1
        q_start = await acq._dry_run(k, seq, view.center, float(grasp.width), failures)
        if q_start is None:
            continue
        outcome = await _execute(acq, k, gi, seq, q_start, box, failures, grasp)
        if outcome is not None:
            return outcome
    acq.decide("no lay-down executable", checks=sum(checks), not_lower=lower_only)
    return None


async def _execute(acq: Acquisition, k: int, gi: int, seq: LayDownPoses, q_start: np.ndarray,
                   box: tuple[np.ndarray, np.ndarray], failures: list[str], grasp: Any) -> State | None:
    acq.j.laid_down = {**as_recorded(seq), "from_view": k}
    outcome = await acq._attempt(k, gi, grasp, seq, q_start, box, f"{grasp.kind}:{gi}:{seq.name}", failures)
    if (acq.j.laid_down or {}).get("state") != "done":  # refused before the hold, or it slipped: not laid down
        acq.j.laid_down = None
        return outcome
    c, e = object_box(seq.lying_center, seq.lying_height, seq.lying_corners, acq.config.turn.object_box_margin)
    await acq.cell.set_object_box(c, e)  # where it now lies, for the moves to the next scan poses
    return outcome


def record_laid_down(acq: Acquisition, k: int) -> None:
    """The object was released lying: set the standing views 0..``k`` aside, restart the views at 0 where it
    lies (its expected centre and height from the plan), and say so in the journal."""
    j = acq.j
    entry = dict(j.laid_down or {})
    center = [float(x) for x in entry.get("center", j.centers.get(str(k), [0.0, 0.0, 0.0]))]
    height = float(entry.get("height", j.heights.get(str(k), 0.1)))
    restart_views(acq.store.path, j, k, "standing", center, height)  # the standing pose's views, kept apart
    entry.update(state="done", from_view=k)
    j.laid_down = entry
    j.counters.lay_downs += 1
    j.state = "scan"
    acq.decide("laid on its side: the views restart where it lies (the standing views are kept aside)",
               pose=entry.get("pose"), center=center, height=height, from_view=k)
    acq.store.save_journal(j.to_dict())
