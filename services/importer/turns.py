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

With the closing pair (first view onto the last) and the pairs further apart, the turns are then solved
jointly over the view graph, checked by the loop (``turn_graph``): a full-turn sequence's turns add up to a
full turn, a given step stays within its stated uncertainty, and what is unsure is said.

The dynamic stage then refines every turn; these are its priors ("commanded" turns in ``session.json``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from services.importer.turn_graph import LoopVerdict, TurnGraphConfig, edge_from_search, solve_turns
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
    loop: LoopVerdict | None = None  # the view graph's verdict (turn_graph.py): solved turns, loop, unsure pairs

    @property
    def status(self) -> str:
        """"closed" | "open" | "unsure" (``turn_graph``); "open" without a graph."""
        return self.loop.status if self.loop is not None else "open"

    @property
    def total_turn_deg(self) -> float:
        """The solved total turn (+-360 when the loop closes), else the cumulative turns' sum."""
        return self.loop.total_turn_deg if self.loop is not None else float(self.cumulative_deg[-1])

    def to_json(self) -> dict:
        out = {"cumulative_deg": [round(c, 3) for c in self.cumulative_deg], "source": self.source,
               "direction": self.direction, "direction_source": self.direction_source,
               "pair_turn_deg": [round(y, 2) for y in self.pair_yaw_deg],
               "pair_fitness": [round(f, 3) for f in self.pair_fitness], "replaced_pairs": self.replaced,
               "direction_support": self.support, "status": self.status}
        if self.loop is not None:
            out["loop"] = self.loop.to_json()
        return out


def pair_searches(views: list[DynamicView], config: TurnSearchConfig | None = None) -> list[TurnResult]:
    """4-DoF search of view k+1 onto view k for every consecutive pair (centres stacked, no turn assumed)."""
    return [search_pair(views[k], views[k + 1], config) for k in range(len(views) - 1)]


def search_pair(target: DynamicView, source: DynamicView, config: TurnSearchConfig | None = None) -> TurnResult:
    """4-DoF search of ``source`` onto ``target`` over the full circle (centres stacked, no turn assumed)."""
    axis = np.asarray(target.table.normal, dtype=float)
    prior = prerotation(DynamicView(source.xyz, source.rgb, source.table, source.center, 0.0, source.normals),
                        target.center, axis)
    return search_turn(_cloud(source), _cloud(target), axis, target.center, prior=prior, config=config)


def graph_searches(views: list[DynamicView], reach: int, config: TurnSearchConfig | None = None
                   ) -> tuple[TurnResult, dict[tuple[int, int], TurnResult]]:
    """The view graph's searches beyond the neighbours: the closing pair (the first view onto the last) and
    each view onto the ones ``2..reach`` further on, past the end too (they overlap when the loop closes)."""
    n = len(views)
    closing = search_pair(views[-1], views[0], config)
    further = {}
    for d in range(2, min(reach, n - 2) + 1):  # beyond n - 2 a pair is a neighbour pair the other way round
        for i in range(n):
            further[(i, (i + d) % n)] = search_pair(views[i], views[(i + d) % n], config)
    return closing, further


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


def plan_turns(searches: list[TurnResult], step_deg: float | None, direction: str,
               closing: TurnResult | None = None, further: dict[tuple[int, int], TurnResult] | None = None,
               step_sigma_deg: float | None = None, graph: TurnGraphConfig | None = None) -> TurnPlan:
    """Cumulative commanded turns for the views from the pair searches and what the user told us.

    With the closing search (the first view onto the last) and optionally ``further`` pairs (``(i, j)``:
    view j onto view i), the turns are solved jointly over the view graph with the loop (``turn_graph``):
    the plan's turns are then the solved ones and ``loop`` says whether the sequence closes, and what is
    unsure. Without them, the neighbour estimates alone (as below)."""
    plan = _plan_from_neighbours(searches, step_deg, direction)
    if closing is None:
        return plan
    cfg = graph or TurnGraphConfig()
    n = len(searches) + 1
    edges = [edge_from_search(k, k + 1, False, r, cfg) for k, r in enumerate(searches)]
    for (i, j), r in sorted((further or {}).items()):
        edges.append(edge_from_search(i, j, j < i, r, cfg))
    closing_edge = edge_from_search(n - 1, 0, True, closing, cfg)
    # the direction: the user's; else the loop's (both solved, the cheaper kept); else the plan's evidence
    open_turns = list(np.diff(plan.cumulative_deg))
    verdict = solve_turns(n, edges, closing_edge, direction, step_deg, step_sigma_deg, cfg, open_turns,
                          open_direction=plan.direction)
    plan.loop = verdict
    plan.cumulative_deg = list(verdict.cumulative_deg)
    if verdict.loop_closes:
        plan.direction = "ccw" if verdict.total_turn_deg > 0 else "cw"
        plan.support = {**plan.support, "loop_costs": verdict.direction_costs}
    return plan


def _plan_from_neighbours(searches: list[TurnResult], step_deg: float | None, direction: str) -> TurnPlan:
    """The plan from the neighbour pairs alone: the given step (direction given or from the sweeps), or each
    pair's estimate with outliers replaced by the median turn."""
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
