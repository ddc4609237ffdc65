"""A 1-D yaw search about the turn axis that lets colour fix what geometry leaves free (fast pair path).

Why: the fast path's coarse-to-fine colour ICP converges on geometry first. On a body of revolution (a can)
geometry does not constrain the yaw about its axis at all, and the colour ICP's gradient term (on the
8-colour quantised clouds, 6 -> 2 mm voxels) then settles 2-5 degrees off, consistently to one side: on the
realistic twin's alphabet soup every one of 11 edges was off by -0.3...+5.4 degrees, +24.7 degrees summed
round the loop (``bench.pair_yaw``), although the clouds' colour agreement itself peaks within 0.5 degrees of
the true yaw on every edge. So after the local refinement, the yaw about the table normal through the
object centre is searched directly, each hypothesis scored by the pair's own score (geometric fitness plus
colour agreement on the evaluation clouds): on a can the colour term decides; on a box the geometric
fitness falls off within a degree or two of its optimum and keeps the ICP's yaw.

Coarse to fine: every ``steps_deg[0]`` over +-``range_deg``, then every next step within one step of the best
so far. The rotation is about the line through ``center`` along ``axis``; since that estimated centre is not
the object's own axis, each hypothesis's translation is re-fitted (``refit``) before it is scored.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from common.geometry import rotation_about_line
from services.registration.dynamic.views import DynamicRegistrationError

Score = Callable[[np.ndarray], float]


@dataclass(frozen=True)
class YawRefineConfig:
    """Search range and steps (degrees, coarse to fine); ``enabled=False`` keeps the ICP's yaw.

    The pair scores a yaw by ``-(colour difference) - plane_rmse_weight x point-to-plane rmse (mm)`` among
    yaws whose geometric fitness is within ``fitness_drop`` of the ICP result's. Measured on the realistic
    twin (true yaw +- 8 deg): a can's mean chromaticity difference is ~0.035-0.07 at the true yaw and
    0.08-0.12 at 8 deg off, its plane rmse flat (0.47-0.52 mm); a box's plane rmse rises 0.4 -> 1.5 mm and its
    colour difference 0.09 -> 0.25. The fitness is no score here: on a partial view it grows with the
    overlap (sauce: 0.90 at -8 deg, 0.95 at +8), which is what pulls the colour ICP to one side.
    """

    enabled: bool = True
    # colour ICP's yaw error on the realistic cans: up to 16 deg before this search (tomato sauce, one edge)
    range_deg: float = 16.0
    steps_deg: tuple[float, ...] = (2.0, 0.5, 0.25)  # each level searches +- the previous step about the best
    plane_rmse_weight: float = 0.05  # per mm: a box's 1 mm rise (4 deg off) weighs like 0.05 of colour
    fitness_drop: float = 0.1  # guard: a yaw may not lose more geometric fitness than this

    def __post_init__(self) -> None:
        st = self.steps_deg
        if not (st and all(a >= b > 0 for a, b in zip(st, st[1:], strict=False)) and 0 < st[0] <= self.range_deg
                and st[-1] > 0):
            raise DynamicRegistrationError(
                f"yaw refine needs 0 < steps_deg[-1] <= ... <= steps_deg[0] <= range_deg, got {st}, {self.range_deg}",
                code="bad_value", detail={"steps_deg": list(st), "range_deg": self.range_deg})


@dataclass
class YawRefineResult:
    """The refined transform, the yaw offset applied (deg) and the scores before and after."""

    T: np.ndarray
    offset_deg: float
    score_before: float
    score_after: float


def refine_yaw(T: np.ndarray, score: Score, axis: np.ndarray, center: np.ndarray,
               config: YawRefineConfig | None = None,
               refit: Callable[[np.ndarray], np.ndarray] | None = None) -> YawRefineResult:
    """The yaw about ``axis`` through ``center`` (applied after ``T``) that maximises ``score``.

    ``score(T) -> float``, higher is better. ``refit`` (optional) re-fits each hypothesis's translation
    before it is scored (the rotation line through an estimated centre is not the object's own axis).
    Returns ``T`` itself (offset 0) when no hypothesis beats it.
    """
    cfg = config or YawRefineConfig()
    T = np.asarray(T, dtype=float)
    base = float(score(T))
    if not cfg.enabled:
        return YawRefineResult(T, 0.0, base, base)
    seen: dict[float, float] = {0.0: base}
    poses: dict[float, np.ndarray] = {0.0: T}

    def at(deg: float) -> float:
        key = round(deg, 6)
        if key not in seen:
            Ty = rotation_about_line(axis, center, np.radians(deg)) @ T
            poses[key] = Ty = refit(Ty) if refit is not None else Ty
            seen[key] = float(score(Ty))
        return seen[key]

    best, reach = 0.0, cfg.range_deg
    for step in cfg.steps_deg:  # coarse to fine: +- reach about the best so far
        n = int(np.floor(reach / step + 1e-9))
        best = max((best + k * step for k in range(-n, n + 1)), key=lambda d: (at(d), -abs(d)))
        reach = step
    if at(best) <= base:
        return YawRefineResult(T, 0.0, base, base)
    return YawRefineResult(poses[round(best, 6)], float(best), base, at(best))
