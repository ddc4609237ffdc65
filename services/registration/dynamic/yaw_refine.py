"""A 1-D yaw search about the turn axis that lets colour fix what geometry leaves free (fast pair path).

Why: the fast path's coarse-to-fine colour ICP converges on geometry first. On a body of revolution (a can)
geometry does not constrain the yaw about its axis, and the colour ICP (8-colour quantised clouds, 6 -> 2 mm
voxels) then settled 2-16 degrees off, mostly to one side: on the realistic twin's alphabet soup the 11 chain
edges summed to +24.7 degrees, on the tomato sauce to +40.9 (``bench.pair_yaw``, against the twin's record),
although the clouds' colour agreement peaks within 0.5 degrees of the true yaw on every edge.

So after the local refinement, where geometry leaves the yaw free (``geometry_pins_yaw``: the point-to-plane
rmse barely changes 2 degrees either side; on a box the ICP's yaw stands), the yaw about the table normal
through the object centre is searched directly: every ``steps_deg[0]`` over +-``range_deg``, then each finer
step within one step of the best so far. Each hypothesis's translation is re-fitted (``refit``: the estimated
centre is not the object's own axis) and the pair scores it (``YawRefineConfig`` says how).
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
    # the search runs only where geometry leaves the yaw free: the point-to-plane rmse at +-probe_deg rises on
    # average by at most pinned_rise_mm (realistic twin, +-2 deg: cans -0.02...+0.02 mm, the milk carton
    # +0.24...+0.34 mm). On a box the shape already fixes the yaw and colour would only add its own bias (the
    # real castard box: the loop went 0.46 -> 4.2 deg when colour was allowed to move every edge)
    probe_deg: float = 2.0
    pinned_rise_mm: float = 0.05
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


def geometry_pins_yaw(T: np.ndarray, plane_rmse_mm: Callable[[np.ndarray], float], axis: np.ndarray,
                      center: np.ndarray, config: YawRefineConfig | None = None,
                      refit: Callable[[np.ndarray], np.ndarray] | None = None) -> tuple[bool, float]:
    """(whether the shape fixes the yaw, the mean rise in mm): the point-to-plane rmse at +-``probe_deg`` about
    ``axis`` through ``center`` against its value at ``T`` (each pose's shift re-fitted by ``refit``)."""
    cfg = config or YawRefineConfig()
    fit = refit or (lambda M: M)
    p0 = plane_rmse_mm(fit(np.asarray(T, dtype=float)))
    side = [plane_rmse_mm(fit(rotation_about_line(axis, center, np.radians(d)) @ T))
            for d in (-cfg.probe_deg, cfg.probe_deg)]
    rise = 0.5 * (side[0] + side[1]) - p0
    return bool(rise > cfg.pinned_rise_mm), float(rise)


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
