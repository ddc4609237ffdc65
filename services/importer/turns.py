"""The turn between consecutive views of a fixed-camera sequence: given, estimated, and its direction.

Each view is isolated by the static stage (one frame, ``base`` from the table), then each consecutive pair
goes through the 4-DoF turn search (``registration.dynamic.turn4dof.search_turn``) over the full circle.
The yaw that maps view k+1 back onto view k is minus the object's turn between them.

- **step given, direction known**: commanded turns are ``step * k`` with the sign of the direction.
- **step given, direction unknown**: both signs are tried on every pair: the sweep's best score within
  half a step of +step and of -step, summed over the pairs; the sign with the larger sum is kept (a
  turntable's direction is the same for every step, so one wrong pair cannot flip it).
- **no step**: the per-pair estimates are used, cumulated; a pair whose estimate disagrees with the
  median turn by more than ``max(10 deg, half the median)`` (a symmetric face matched the wrong way, an
  object too featureless to tell) takes the median instead. The direction comes with the estimate.

The dynamic stage then refines every turn; these are its priors ("commanded" turns in ``session.json``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from services.registration.api import Cloud, DynamicView, TurnResult, TurnSearchConfig, prerotation, search_turn

DIRECTIONS = ("ccw", "cw", "unknown")


@dataclass
class TurnPlan:
    """Cumulative turns per view (deg, counter-clockwise seen from above) and how they were decided."""

    cumulative_deg: list[float]
    source: str  # "given" | "estimated"
    direction: str  # "ccw" | "cw"
    direction_source: str  # "given" | "estimated"
    pair_yaw_deg: list[float] = field(default_factory=list)  # per pair, the object's turn found by the search
    pair_fitness: list[float] = field(default_factory=list)
    replaced: list[int] = field(default_factory=list)  # pairs whose estimate was replaced by the median
    support: dict = field(default_factory=dict)  # direction evidence

    def to_json(self) -> dict:
        return {"cumulative_deg": [round(c, 3) for c in self.cumulative_deg], "source": self.source,
                "direction": self.direction, "direction_source": self.direction_source,
                "pair_turn_deg": [round(y, 2) for y in self.pair_yaw_deg],
                "pair_fitness": [round(f, 3) for f in self.pair_fitness], "replaced_pairs": self.replaced,
                "direction_support": self.support}


def pair_searches(views: list[DynamicView], config: TurnSearchConfig | None = None) -> list[TurnResult]:
    """4-DoF search of view k+1 onto view k for every consecutive pair (centres stacked, no turn assumed)."""
    out = []
    for s, t in zip(views[1:], views[:-1], strict=True):
        axis = np.asarray(t.table.normal, dtype=float)
        prior = prerotation(DynamicView(s.xyz, s.rgb, s.table, s.center, 0.0, s.normals), t.center, axis)
        out.append(search_turn(_cloud(s), _cloud(t), axis, t.center, prior=prior, config=config))
    return out


def _cloud(v: DynamicView) -> Cloud:
    nrm = v.normals if v.normals is not None else np.zeros_like(v.xyz)
    return Cloud(np.asarray(v.xyz, np.float32), np.asarray(v.rgb, np.uint8), np.asarray(nrm, np.float32))


def _window_best(sweep: list[tuple[float, float]], centre: float, half: float) -> float:
    """Best sweep score within ``half`` degrees of ``centre`` (angles wrapped)."""
    best = 0.0
    for yaw, score in sweep:
        if abs((yaw - centre + 180.0) % 360.0 - 180.0) <= half:
            best = max(best, score)
    return best


def plan_turns(searches: list[TurnResult], step_deg: float | None, direction: str) -> TurnPlan:
    """Cumulative commanded turns for the views from the pair searches and what the user told us."""
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {DIRECTIONS}, got {direction!r}")
    turns = [-r.yaw_deg for r in searches]  # the object's turn: minus the yaw that maps it back
    fitness = [r.fitness for r in searches]
    support: dict = {}
    if step_deg is not None:
        step = abs(float(step_deg))
        if direction == "unknown":
            half = max(step / 2.0, 5.0)
            # turning by +step moves view k+1 so that a yaw of -step maps it back onto view k
            plus = sum(_window_best(r.sweep, -step, half) for r in searches)
            minus = sum(_window_best(r.sweep, step, half) for r in searches)
            support = {"ccw_score": round(plus, 3), "cw_score": round(minus, 3)}
            sign, dsrc = (1.0 if plus >= minus else -1.0), "estimated"
        else:
            sign, dsrc = (1.0 if direction == "ccw" else -1.0), "given"
        cum = [sign * step * k for k in range(len(searches) + 1)]
        return TurnPlan(cum, "given", "ccw" if sign > 0 else "cw", dsrc, turns, fitness, [], support)
    med = float(np.median(turns))
    if direction != "unknown":
        sign = 1.0 if direction == "ccw" else -1.0
        if med * sign < 0:  # the estimate runs the other way: trust the user, use magnitudes
            turns = [sign * abs(t) for t in turns]
            med = float(np.median(turns))
    tol = max(10.0, 0.5 * abs(med))
    replaced = [k for k, t in enumerate(turns) if abs(t - med) > tol]
    used = [med if k in replaced else t for k, t in enumerate(turns)]
    cum = [0.0] + list(np.cumsum(used))
    support = {"positive_pairs": int(sum(t > 0 for t in turns)), "negative_pairs": int(sum(t < 0 for t in turns)),
               "median_turn_deg": round(med, 2)}
    dsrc = "estimated" if direction == "unknown" else "given"
    return TurnPlan([float(c) for c in cum], "estimated", "ccw" if med >= 0 else "cw", dsrc, turns, fitness,
                    replaced, support)
