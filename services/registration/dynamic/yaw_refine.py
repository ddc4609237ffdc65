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

Coarse to fine: every ``step_deg`` over +-``range_deg``, then every ``fine_step_deg`` within one coarse step of
the best. The rotation is about the line through ``center`` along ``axis``; a centre estimate a centimetre
off the can's true axis moves its surface by ~0.5 mm per 3 degrees, well inside the score's inlier distance.
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
    """Search range and steps (degrees); ``enabled=False`` keeps the ICP's yaw."""

    enabled: bool = True
    range_deg: float = 8.0  # colour ICP's yaw error on the cans: up to 5.4 deg
    step_deg: float = 1.0
    fine_step_deg: float = 0.25
    fitness_tolerance: float = 0.03  # a yaw may lower the geometric fitness by this much (a box's yaw is geometric)

    def __post_init__(self) -> None:
        if not (0 < self.fine_step_deg <= self.step_deg <= self.range_deg):
            raise DynamicRegistrationError("yaw refine needs 0 < fine_step_deg <= step_deg <= range_deg, got "
                             f"{self.fine_step_deg}, {self.step_deg}, {self.range_deg}", code="bad_value")


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

    n = int(np.floor(cfg.range_deg / cfg.step_deg + 1e-9))
    coarse = [k * cfg.step_deg for k in range(-n, n + 1)]
    best = max(coarse, key=lambda d: (at(d), -abs(d)))
    m = int(np.floor(cfg.step_deg / cfg.fine_step_deg + 1e-9))
    fine = [best + k * cfg.fine_step_deg for k in range(-m, m + 1)]
    best = max(fine, key=lambda d: (at(d), -abs(d)))
    if at(best) <= base:
        return YawRefineResult(T, 0.0, base, base)
    return YawRefineResult(poses[round(best, 6)], float(best), base, at(best))
