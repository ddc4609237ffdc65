"""Which scan poses the arm reaches around an object: the dry runs behind choosing a view's scan poses and
behind refusing a set-down spot the next view could not be scanned at.

Its own module because it only asks the arm (dry runs, nothing moves) and answers; the state machine decides
what to do with the answer (scan there, fail the view, try another spot).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from common.errors import RemoteError
from services.orchestrator.limits import ARM_UNAVAILABLE_CODES, name_scan_pose_limit
from services.orchestrator.planning import scan_pose_candidates


async def first_reachable_scan_set(cell: Any, scan_config: Any, center: np.ndarray, height: float,
                                   start_q: np.ndarray | None = None) -> tuple[list[np.ndarray] | None, list[str]]:
    """The first candidate set of scan poses around an object at ``center`` whose every pose the arm
    reaches (dry runs, from ``start_q`` when given, else from the current posture), and the refusals."""
    reasons: list[str] = []
    for candidate in scan_pose_candidates(center, height, scan_config):
        try:
            for T in candidate:
                await cell.move("pose", target=T, q=start_q, frame="camera", dry_run=True)
        except RemoteError as exc:
            if exc.code in ARM_UNAVAILABLE_CODES:
                raise
            reasons.append(exc.code)
            continue
        return candidate, reasons
    return None, reasons


async def scannable_spot(cell: Any, scan_config: Any, spot: np.ndarray, height: float, cache: dict[tuple, bool],
                         decide: Callable[..., None]) -> bool:
    """Whether the object set down at ``spot`` can be scanned there: a relocated set-down that leaves no
    reachable set of scan poses would end the acquisition at the next view, so such a spot is never
    chosen. Checked from the home posture, where the next view's scan poses are planned from; ``cache``
    keeps the answer per spot (rounded to a millimetre) for one view's search."""
    key = tuple(np.round(np.asarray(spot, float)[:2], 3))
    if key not in cache:
        try:
            start_q: np.ndarray | None = np.asarray((await cell.move("home", dry_run=True)).q, float)
        except RemoteError as exc:
            if exc.code in ARM_UNAVAILABLE_CODES:
                raise
            start_q = None  # the way home is blocked from here: plan from the current posture instead
        candidate, reasons = await first_reachable_scan_set(cell, scan_config, np.asarray(spot, float), height,
                                                            start_q)
        cache[key] = candidate is not None
        if candidate is None:
            decide("relocated spot leaves no reachable scan poses", spot=list(key),
                   limit=name_scan_pose_limit(reasons))
    return cache[key]
