"""The turns of a fixed-camera sequence solved jointly over a view graph, checked by the loop.

Why: estimating each turn from its two neighbouring views alone lets one wrong pair (a symmetric face
matched the wrong way, a featureless side, a large step with little overlap) put the whole sequence
wrong, and nothing notices: a hand-turned box whose pair estimates summed to 36 degrees for a full turn
gave a model open by 27 degrees. A sequence carries two checks the pairs alone do not use:

- **the loop**: when the last view overlaps the first (the closing pair's 4-DoF search fits, with a turn
  no larger than ``closing_max_steps`` mean steps of a full turn), the object came back to where it
  started, so the turns add up to one full turn (+-360 degrees, the sign is the direction);
- **redundancy**: views further apart than neighbours overlap too (``reach``: view k with k+2, ...),
  so each turn is measured more than once.

Every measured pair is an edge ``i -> j`` saying "the object turned by ``m`` degrees from view i to view
j", with alternatives: the search's sweep peaks that score nearly as well (a look-alike turn). The view
angles are solved by iteratively reweighted least squares (Cauchy weights), the first view at 0 and,
when the loop closes, a virtual view n at +-360; each edge takes the alternative nearest the current
solution. One bad edge then gets a small weight and cannot open the loop. Without a given direction both
signs are solved and the cheaper kept.

A **given turntable step** is a strong prior: every neighbour turn is ``step`` within its stated
uncertainty ``step_sigma_deg``; a pair estimate further off than that is not allowed to move it (it is
reported as disagreeing), and the solved turns are kept inside the uncertainty.

The verdict (``status``): ``closed`` (the loop closes and the turns are supported by their estimates),
``open`` (no loop to check: not a full turn or the last view does not overlap the first; the turns are
the estimates) or ``unsure``, with the reasons and the pairs that are unsure and why (look-alike turns,
little overlap, an estimate the solution contradicts). An unsure sequence must not yield an accepted
model (``reconstruct`` reads the status from ``session.json``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from services.registration.api import TurnResult


@dataclass(frozen=True)
class TurnGraphConfig:
    """How the view graph is built and solved, and when a sequence or a pair is unsure."""

    reach: int = 2  # edges from each view to the next ``reach`` views (1: neighbours only)
    closing_min_fitness: float = 0.3  # the last view overlaps the first: its search fits at least this much
    closing_max_steps: float = 1.5  # ... with a turn of at most this many mean steps of a full turn (360/n)
    pair_sigma_deg: float = 3.0  # 1 sigma of a refined pair turn
    alternative_sigma_deg: float = 6.0  # 1 sigma of a sweep peak (the sweep's grid is coarse)
    step_sigma_deg: float = 2.0  # stated uncertainty of a given step, when the caller gives none
    spread_sigma_deg: float = 30.0  # weak prior of a closed loop without a step: turns near the mean step
    cauchy_sigmas: float = 2.0  # Cauchy weight scale, in sigmas
    outlier_sigmas: float = 3.0  # an edge further than this from the solution is an outlier
    iterations: int = 30
    alternative_ratio: float = 0.85  # a sweep peak scoring this share of the best is a look-alike turn
    min_separation_deg: float = 20.0  # ... and at least this far from the best
    # more look-alikes than this (a sweep with no turn standing out: a body of revolution, no texture) cannot
    # be resolved by the loop; fewer (a box's 90/180-degree twins) are, when the solution admits only one
    max_lookalikes: int = 3
    closing_tolerance_deg: float = 30.0  # the closing pair fits a full turn when this close to where it leaves it
    direction_margin: float = 2.0  # both directions' costs closer than this: the direction is not told
    backward_tolerance_deg: float = 5.0  # an estimate this far the other way is noise on a small turn, not wrong
    min_turn_deg: float = 0.5  # a turn solved the wrong way is held at this much the right way
    # two neighbouring views overlap, so they are less than this apart: a solved turn beyond it is held at
    # it (without it a robust solve may load a whole missing turn onto one pair)
    max_turn_deg: float = 150.0
    max_uneven: float = 3.0  # a solved turn above this x the median turn (+ 10 deg) is not a turn made by hand
    min_fitness: float = 0.25  # a pair fitting less than this overlaps too little to tell its turn
    min_supported: float = 0.5  # a closed loop needs this share of turns supported by their own best estimate
    max_contradicted: float = 1.0 / 3.0  # ... and at most this share contradicted by the solution
    max_ambiguous: float = 0.5  # more look-alike turns than this share: the object does not tell its turn

    def __post_init__(self) -> None:
        if self.reach < 1 or self.iterations < 1:
            raise ValueError("reach and iterations must be at least 1")
        if min(self.pair_sigma_deg, self.alternative_sigma_deg, self.step_sigma_deg, self.spread_sigma_deg) <= 0:
            raise ValueError("sigmas must be positive")


@dataclass
class Edge:
    """A measured pair: the object's turn from view ``i`` to view ``j`` (``wraps``: j comes after the last
    view, i.e. past the full turn), its alternatives (turn, sigma) best first, and how it fits."""

    i: int
    j: int
    wraps: bool
    candidates: list[tuple[float, float]]
    fitness: float
    ambiguous: str = ""  # why the turn is ambiguous (a look-alike turn), empty when it is not

    @property
    def best(self) -> float:
        return self.candidates[0][0]


def wrap(deg: float | np.ndarray) -> float | np.ndarray:
    """Angles in degrees into [-180, 180)."""
    return (np.asarray(deg) + 180.0) % 360.0 - 180.0 if isinstance(deg, np.ndarray) else (deg + 180.0) % 360.0 - 180.0


def edge_from_search(i: int, j: int, wraps: bool, r: TurnResult, cfg: TurnGraphConfig) -> Edge:
    """An edge from the 4-DoF search of view j onto view i (``r.yaw_deg`` maps j back onto i, so the object
    turned by minus it); the sweep's other peaks that score nearly as well are its alternatives."""
    best = float(wrap(-r.yaw_deg))
    cands = [(best, cfg.pair_sigma_deg)]
    why = ""
    if r.sweep:
        yaws = np.array([y for y, _ in r.sweep], dtype=float)
        scores = np.array([s for _, s in r.sweep], dtype=float)
        order = np.argsort(yaws)
        yaws, scores = yaws[order], scores[order]
        top = float(scores.max()) if len(scores) else 0.0
        peaks = [k for k in range(len(scores))
                 if scores[k] >= scores[k - 1] and scores[k] >= scores[(k + 1) % len(scores)]]
        for k in sorted(peaks, key=lambda k: -scores[k]):
            turn = float(wrap(-yaws[k]))
            if top <= 0 or scores[k] < cfg.alternative_ratio * top:
                continue
            if all(abs(wrap(turn - c)) >= cfg.min_separation_deg for c, _ in cands):
                cands.append((turn, cfg.alternative_sigma_deg))
                if not why:
                    why = (f"look-alike turn: {turn:+.0f} deg scores {scores[k] / top:.0%} of the best "
                           "(symmetric or low-texture object)")
    return Edge(i, j, wraps, cands, float(r.fitness), why)


@dataclass
class GraphSolution:
    """The solved view angles and how each edge sits in them."""

    angles: np.ndarray  # (n,) deg, view 0 at 0
    winding: int  # +-1: the sequence closes a full turn that way; 0: open
    cost: float
    chosen: list[float]  # per edge, the alternative used
    residual: list[float]  # per edge, deg
    inlier: list[bool]
    edges: list[Edge]  # the edges used (a wrapping edge is used only when the loop closes)
    fitting: list[int]  # per edge, how many of its alternatives the solution admits (2+: still ambiguous)


def solve_graph(n: int, edges: list[Edge], winding: int, cfg: TurnGraphConfig,
                step: float | None = None, step_sigma: float | None = None,
                init: np.ndarray | None = None) -> GraphSolution:
    """View angles (deg) from the edges by IRLS; ``winding`` +-1 fixes a virtual view n at 360 * winding
    (the loop), 0 leaves the sequence open (wrapping edges unused). ``step`` (signed) adds a prior on every
    neighbour turn with ``step_sigma``; without a step, a closed loop adds a weak prior toward its mean step."""
    m = n + 1 if winding else n  # unknowns 1..m-1 (view 0 fixed at 0; view n fixed at 360 * winding)
    # edges between views further apart than neighbours are used only when they overlap enough to tell
    used = [e for e in edges if (winding or not e.wraps) and (e.j == (e.i + 1) % n or e.fitness >= cfg.min_fitness)]
    if init is not None:
        theta = np.asarray(init, dtype=float).copy()
    elif step is not None:
        theta = step * np.arange(n, dtype=float)
    else:
        theta = 360.0 * winding * np.arange(n, dtype=float) / n
    full = 360.0 * winding
    # the object is turned one way (by hand or by a turntable): every turn, and so every edge from an earlier
    # to a later view, has the direction's sign; an alternative the other way (beyond a small tolerance for
    # noise on tiny steps) is not one
    sign = int(winding) if winding else (int(np.sign(step)) if step else 0)

    def allowed(e: Edge) -> list[tuple[float, float]]:
        return [cs for cs in e.candidates if not sign or cs[0] * sign > -cfg.backward_tolerance_deg]

    def pos(k: int, wraps: bool) -> int:
        return n if wraps else k

    priors: list[tuple[int, int, float, float]] = []  # (a, b, turn, sigma): theta_b - theta_a = turn
    if step is not None:
        sig = step_sigma if step_sigma is not None else cfg.step_sigma_deg
        priors += [(k, k + 1, step, sig) for k in range(m - 1)]
    elif winding:
        priors += [(k, k + 1, full / n, cfg.spread_sigma_deg) for k in range(m - 1)]
    pinned: set[int] = set()  # turns solved the wrong way: held at the smallest turn the right way
    capped: set[int] = set()  # turns solved beyond max_turn_deg: held at it
    chosen = [e.best for e in used]
    for _ in range(cfg.iterations):
        ext = np.append(theta, full) if winding else theta
        rows, rhs, w = [], [], []
        for q, e in enumerate(used):
            cands = allowed(e)
            if not cands:
                continue
            a, b = e.i, pos(e.j, e.wraps)
            pred = ext[b] - ext[a]
            # two views that overlap are less than half a turn apart: a turn is its estimate, never that
            # plus a whole turn (which would let any edge absorb a full turn unseen)
            c, sig = min(cands, key=lambda cs: abs(cs[0] - pred))
            chosen[q] = c
            r = (c - pred) / sig
            rows.append((a, b)), rhs.append(c), w.append(1.0 / (1.0 + (r / cfg.cauchy_sigmas) ** 2) / sig**2)
        held = [(k, k + 1, sign * cfg.min_turn_deg, 0.5) for k in sorted(pinned)]
        held += [(k, k + 1, sign * cfg.max_turn_deg, 0.5) for k in sorted(capped)]
        for a, b, turn, sig in priors + held:
            rows.append((a, b)), rhs.append(turn), w.append(1.0 / sig**2)
        A = np.zeros((len(rows), m))
        for r_, (a, b) in enumerate(rows):
            A[r_, b] += 1.0
            A[r_, a] -= 1.0
        y = np.asarray(rhs, dtype=float)
        if winding:  # the virtual view is fixed: move its column to the right-hand side
            y = y - A[:, n] * full
        sw = np.sqrt(np.asarray(w))
        sol, *_ = np.linalg.lstsq((A[:, 1:n]) * sw[:, None], y * sw, rcond=None)
        new = np.concatenate([[0.0], sol])
        turns = np.diff(np.append(new, full) if winding else new)
        wrong = {k for k, t in enumerate(turns) if sign and t * sign < cfg.min_turn_deg - 1e-6} - pinned
        far = {k for k, t in enumerate(turns) if sign and t * sign > cfg.max_turn_deg + 1e-6} - capped
        pinned |= wrong
        capped |= far
        if not wrong and not far and np.max(np.abs(new - theta)) < 1e-4:
            theta = new
            break
        theta = new
    ext = np.append(theta, full) if winding else theta
    residual, inlier, fitting, cost = [], [], [], 0.0
    for e, c in zip(used, chosen, strict=True):
        pred = ext[pos(e.j, e.wraps)] - ext[e.i]
        res = float(c - pred)
        sig = dict(e.candidates)[c]
        ok = bool(allowed(e))
        residual.append(res)
        inlier.append(ok and abs(res) <= cfg.outlier_sigmas * max(sig, cfg.pair_sigma_deg))
        fitting.append(sum(abs(a - pred) <= cfg.outlier_sigmas * max(sa, cfg.pair_sigma_deg)
                           for a, sa in allowed(e)))
        # robust and bounded: an outlier costs the same however far off (or the wrong way), so the
        # hypotheses compare by how many edges they explain, not by how wild the ones they do not explain are
        cap = float(np.log1p((cfg.outlier_sigmas / cfg.cauchy_sigmas) ** 2))
        cost += min(cap, float(np.log1p((res / (cfg.cauchy_sigmas * sig)) ** 2))) if ok else cap
        cost += 0.0 if c == e.best else 1.0  # an alternative is less likely than the best
    return GraphSolution(theta, winding, cost, list(chosen), residual, inlier, used, fitting)


@dataclass
class LoopVerdict:
    """What the graph says about the sequence: its turns, the loop, and what is unsure."""

    status: str  # "closed" | "open" | "unsure"
    cumulative_deg: list[float]
    turns_deg: list[float]  # per neighbour pair, the solved turn
    loop_closes: bool
    closing: dict
    total_turn_deg: float  # the turns plus, when the loop closes, the closing turn: +-360 then
    unsure_pairs: list[dict] = field(default_factory=list)
    disagreeing_pairs: list[dict] = field(default_factory=list)  # estimates the given step overruled
    reasons: list[str] = field(default_factory=list)
    edges: list[dict] = field(default_factory=list)
    direction_costs: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"status": self.status, "loop_closes": self.loop_closes,
                "total_turn_deg": round(self.total_turn_deg, 2), "closing": self.closing,
                "solved_turn_deg": [round(t, 2) for t in self.turns_deg], "unsure_pairs": self.unsure_pairs,
                "disagreeing_pairs": self.disagreeing_pairs, "reasons": self.reasons,
                "edges": self.edges, "direction_costs": self.direction_costs}


def loop_closes(n: int, closing: Edge | None, cfg: TurnGraphConfig) -> tuple[bool, dict]:
    """Does the last view overlap the first? (The closing search fits, with a turn of at most
    ``closing_max_steps`` mean steps of a full turn, which a partial turn's closing pair cannot have.)"""
    if closing is None:
        return False, {"why": "no closing pair searched"}
    limit = cfg.closing_max_steps * 360.0 / n
    near = [c for c, _ in closing.candidates if abs(c) <= limit]
    info = {"fitness": round(closing.fitness, 3), "turn_deg": round(closing.best, 2), "max_turn_deg": round(limit, 1)}
    if closing.fitness < cfg.closing_min_fitness:
        return False, {**info, "why": f"the last view overlaps the first too little ({closing.fitness:.2f} < "
                                      f"{cfg.closing_min_fitness})"}
    if not near:
        return False, {**info, "why": f"the last view is {closing.best:+.0f} deg from the first: more than "
                                      f"{cfg.closing_max_steps:g} mean steps of a full turn (a partial turn)"}
    return True, info


def _edge_json(e: Edge, sol: GraphSolution | None, q: int | None) -> dict:
    d = {"from": e.i, "to": e.j, "estimate_deg": round(e.best, 2), "fitness": round(e.fitness, 3)}
    if e.wraps:
        d["wraps"] = True
    if sol is not None and q is not None:
        d.update(used_deg=round(sol.chosen[q], 2), residual_deg=round(sol.residual[q], 2), inlier=sol.inlier[q])
    return d


def solve_turns(n: int, edges: list[Edge], closing: Edge | None, direction: str,
                step_deg: float | None = None, step_sigma_deg: float | None = None,
                config: TurnGraphConfig | None = None, open_turns: list[float] | None = None,
                open_direction: str | None = None) -> LoopVerdict:
    """The sequence's turns from its edges (neighbours, further pairs, the closing pair last -> first).

    ``direction`` "ccw" | "cw" | "unknown"; ``step_deg`` a given turntable step (unsigned) with its stated
    uncertainty. ``open_turns``: the neighbour turns to use when the loop does not close (the caller's
    rule for an open sequence; default the neighbour edges' best estimates); ``open_direction`` the direction
    of an open sequence with a step whose direction is unknown (default: the neighbour estimates' median)."""
    cfg = config or TurnGraphConfig()
    closes, closing_info = loop_closes(n, closing, cfg)
    all_edges = list(edges) + ([closing] if closing is not None else [])
    neighbours = {e.i: e for e in edges if e.j == e.i + 1 and not e.wraps}
    if step_deg is not None:
        chain = [(open_direction_sign(direction, open_direction, edges)) * abs(step_deg)] * (n - 1)
    else:
        chain = list(open_turns) if open_turns is not None else [neighbours[k].best for k in range(n - 1)]
    if closes and closing is not None:
        partial = partial_turn(chain, closing, cfg)
        if partial:
            closes, closing_info = False, {**closing_info, "why": partial}
    signs = [1, -1] if direction == "unknown" else [1 if direction == "ccw" else -1]
    sig_step = step_sigma_deg if step_sigma_deg is not None else cfg.step_sigma_deg
    reasons: list[str] = []
    sol, costs = None, {}
    if closes:
        sols = {s: _solve_loop(n, all_edges, s, cfg, None if step_deg is None else s * abs(step_deg), sig_step,
                               chain, closing)
                for s in signs}
        costs = {("ccw" if s > 0 else "cw"): round(x.cost, 3) for s, x in sols.items()}

        best = min(sols.values(), key=lambda x: x.cost)
        q = [k for k, e in enumerate(best.edges) if e is closing][0]
        # the closing pair must match about where the full turn leaves it; "about": a focal length a few
        # percent off biases every pair the same way and opens an otherwise right loop by up to tens of degrees
        # (the self-calibration's range), while a partial turn misses by most of a turn. A given step decides
        # that turn itself (an estimate off the step is one more disagreeing pair)
        if step_deg is None and abs(best.residual[q]) > cfg.closing_tolerance_deg:
            closes, closing_info = False, {**closing_info, "why": (
                f"the last view matches the first at {closing.best:+.0f} deg, {best.residual[q]:+.0f} deg from "
                "where a full turn puts it: a partial turn")}
        else:
            sol = best
            if direction == "unknown" and len(sols) == 2:
                a, b = sorted(x.cost for x in sols.values())
                if b - a < cfg.direction_margin:
                    reasons.append(f"the turns do not tell the direction: a full turn either way fits them "
                                   f"about as well (costs {costs})")
    loop_solved = closes and sol is not None
    angles = list(sol.angles) + [360.0 * sol.winding] if loop_solved else [0.0] + list(np.cumsum(chain))
    turns = [float(angles[k + 1] - angles[k]) for k in range(n - 1)]
    if step_deg is not None:  # the step stands within its stated uncertainty, whatever the estimates say
        sgn = 1.0 if sum(turns) >= 0 else -1.0
        turns = [float(np.clip(t, sgn * abs(step_deg) - sig_step, sgn * abs(step_deg) + sig_step)) for t in turns]
    cum = [0.0] + [float(c) for c in np.cumsum(turns)]
    closing_turn = float(360.0 * sol.winding - cum[-1]) if closes and sol is not None else None
    if closing_turn is not None:
        closing_info["solved_deg"] = round(closing_turn, 2)
    edge_rows, unsure, disagree = [], [], []
    open_sign = float(np.sign(sum(turns)))  # the way the object turns (0: no way to tell)
    used = sol.edges if sol is not None else []
    index = {id(e): q for q, e in enumerate(used)}
    for e in all_edges:
        q = index.get(id(e))
        edge_rows.append(_edge_json(e, sol, q))
        if e.j != (e.i + 1) % n or (e.wraps and not closes):
            continue  # further pairs (and an open sequence's closing pair) support the neighbours, which are judged
        why = []
        # a look-alike turn the solved loop rules out (only one alternative fits it) is resolved; without a loop,
        # one the other way is no alternative (the object turns one way); a sweep with look-alikes all round
        # is not resolved, whatever fits
        flat = len(e.candidates) > 1 + cfg.max_lookalikes
        ahead = [c for c, _ in e.candidates[1:] if c * open_sign > -cfg.backward_tolerance_deg]
        unresolved = bool(ahead) if sol is None else (q is None or sol.fitting[q] != 1)
        if e.ambiguous and (flat or unresolved):
            why.append(f"{e.ambiguous}; {len(e.candidates) - 1} look-alike turns in all" if flat else
                       e.ambiguous if sol is not None or ahead[0] == e.candidates[1][0] else
                       f"look-alike turn: {ahead[0]:+.0f} deg scores nearly as well (symmetric or low-texture object)")
        if e.fitness < cfg.min_fitness:
            why.append(f"little overlap (fitness {e.fitness:.2f} < {cfg.min_fitness})")
        target = (cum[e.j] - cum[e.i]) if not e.wraps else closing_turn
        if q is not None and sol is not None and not sol.inlier[q] and step_deg is None:
            why.append(f"the estimate {e.best:+.1f} deg contradicts the solved turns "
                       f"({sol.residual[q]:+.1f} deg off)")
        elif sol is None and step_deg is None and not e.wraps and \
                abs(e.best - turns[e.i]) > cfg.outlier_sigmas * cfg.pair_sigma_deg:
            why.append(f"the estimate {e.best:+.1f} deg disagrees with the turn used ({turns[e.i]:+.1f} deg)")
        if step_deg is not None and target is not None:
            off = float(wrap(e.best - target))
            if abs(off) > sig_step:
                disagree.append({"from": e.i, "to": e.j, "estimate_deg": round(e.best, 2),
                                 "step_deg": round(target, 2), "off_deg": round(off, 2)})
        if why:
            unsure.append({"from": e.i, "to": e.j, "why": "; ".join(why)})
    status = "closed" if closes else "open"
    n_turns = len(neighbours) + (1 if closes else 0)
    if step_deg is None and closes and sol is not None:
        judged = [(e, q) for e, q in ((e, index.get(id(e))) for e in all_edges)
                  if q is not None and e.j == (e.i + 1) % n]
        supported = sum(1 for e, q in judged if sol.inlier[q] and sol.chosen[q] == e.best)
        contradicted = sum(1 for _, q in judged if not sol.inlier[q])
        if supported < cfg.min_supported * n_turns:
            reasons.append(f"only {supported} of {n_turns} turns are supported by their own estimate: the loop "
                           "is closed by assumption, not by evidence")
        if contradicted > cfg.max_contradicted * n_turns:
            reasons.append(f"{contradicted} of {n_turns} turn estimates contradict the solved turns")
        solved = np.abs(np.asarray(turns + [closing_turn or 0.0]))
        limit = cfg.max_uneven * float(np.median(solved)) + 10.0
        if solved.max() > limit:
            k = int(np.argmax(solved))
            reasons.append(f"the solved turns are uneven: {solved[k]:.0f} deg at pair {k} -> {(k + 1) % n} while "
                           f"the median is {np.median(solved):.0f} deg (the loop's missing turn put on few pairs)")
        reasons += unmeasured_turns(n, sol, turns + [closing_turn or 0.0], cfg)
    if step_deg is None:
        amb = sum(1 for p in unsure if "look-alike" in p["why"])
        if amb > cfg.max_ambiguous * max(1, n_turns):
            reasons.append(f"{amb} of {n_turns} turns have a look-alike turn: the object does not tell its turn "
                           "(symmetric or low texture)")
        # "almost nothing": no more than the closing pair's own tolerance (a full turn's mean step, 360/n, says
        # nothing about a sequence that is not one)
        if not closes and closing is not None and closing.fitness >= cfg.closing_min_fitness \
                and abs(sum(turns)) <= cfg.closing_tolerance_deg:
            reasons.append(f"the last view overlaps the first and the turns add up to only {sum(turns):+.0f} deg: "
                           "the object did not turn, or its turns cannot be seen (symmetric or low texture)")
        if not closes and unsure:
            reasons.append(f"{len(unsure)} turns are unsure and no loop checks them "
                           f"({closing_info.get('why', 'the loop does not close')})")
    elif closes:
        total = abs(step_deg) * n
        if abs(total - 360.0) > abs(step_deg) / 2:
            reasons.append(f"the last view overlaps the first, but {n} x {abs(step_deg):g} deg is {total:.0f} deg, "
                           "not a full turn: the given step or the frames are wrong")
    if reasons:
        status = "unsure"
    total = float(sum(turns)) + (closing_turn or 0.0)
    return LoopVerdict(status, cum, turns, closes, closing_info, total, unsure, disagree, reasons, edge_rows, costs)


def measured_turns(n: int, sol: GraphSolution) -> list[bool]:
    """Per turn of a closed loop (k -> k + 1, the last one n - 1 -> 0), whether the pairs the solution trusts
    (its inliers) measure it, without the full-turn constraint.

    Why: a pair measures the sum of the turns it spans; a turn is measured when some combination of trusted
    pairs isolates it (a pair spanning it, minus pairs spanning the rest). A turn no such combination gives is
    placed by the loop alone, as the full turn minus every other turn: nothing checks it, and whatever the
    other turns got wrong lands on it unseen."""
    rows = []
    for e, ok in zip(sol.edges, sol.inlier, strict=True):
        if not ok:
            continue
        arc = np.zeros(n)
        if e.wraps:
            arc[e.i:] = 1.0
            arc[:e.j] = 1.0
        else:
            arc[e.i:e.j] = 1.0
        rows.append(arc)
    if not rows:
        return [False] * n
    A = np.asarray(rows)
    rank = np.linalg.matrix_rank(A)
    return [bool(np.linalg.matrix_rank(np.vstack([A, np.eye(n)[k]])) == rank) for k in range(n)]


def unmeasured_turns(n: int, sol: GraphSolution, turns: list[float], cfg: TurnGraphConfig) -> list[str]:
    """Why a closed loop is unsure because of a turn only the loop places (``measured_turns``), one reason per
    such turn; ``turns`` the n solved turns, the closing one last.

    A turn the loop alone places is believed when it looks like the turns that were measured (one flipped pair
    among even steps: the loop's remainder is one more such step). When it is larger or smaller than every
    measured turn by more than an estimate's own tolerance (frames missing there: the remainder is several
    steps, which no pair of views confirms), the sequence is unsure."""
    measured = measured_turns(n, sol)
    known = [abs(t) for t, m in zip(turns, measured, strict=True) if m]
    if not known or all(measured):
        return []
    tol = cfg.outlier_sigmas * cfg.pair_sigma_deg
    lo, hi = min(known), max(known)
    return [f"the turn {k} -> {(k + 1) % n} ({t:+.0f} deg) is measured by no trusted pair: only the loop's full "
            f"turn places it, and it is unlike every measured turn ({lo:.0f}-{hi:.0f} deg)"
            for k, (t, m) in enumerate(zip(turns, measured, strict=True))
            if not m and not lo - tol <= abs(t) <= hi + tol]


def _solve_loop(n: int, edges: list[Edge], winding: int, cfg: TurnGraphConfig, step: float | None,
                step_sigma: float, chain: list[float], closing: Edge) -> GraphSolution:
    """The loop solved from two starts, the cheaper kept: even steps, and the estimates themselves.

    Why two: the robust solve keeps the edges its start explains. From even steps a sequence with a gap (frames
    missing: one step three times the others, its searches finding no turn this way) puts the last view a gap
    short of the full turn, the closing pairs look wrong and are weighted out, and the full turn reads as a
    partial one. From the estimates (a turn the other way taken as the median turn, the loop's remainder
    spread over every turn) the closing pairs fit and the gap takes what the loop leaves it."""
    even = solve_graph(n, edges, winding, cfg, step, step_sigma)
    if step is not None or len(chain) != n - 1:
        return even
    ahead = [t for t in chain if t * winding > 0]
    if not ahead:
        return even
    turns = [t if t * winding > 0 else float(np.median(ahead)) for t in chain] + [closing.best]
    turns = np.asarray(turns) + (360.0 * winding - float(np.sum(turns))) / n
    start = solve_graph(n, edges, winding, cfg, step, step_sigma, init=np.concatenate([[0.0], np.cumsum(turns[:-1])]))
    # the closing pair is the loop's evidence: a solution that puts it where it was not found is no full turn
    # (the caller then reads it as a partial one), so one that honours it is preferred, the cheaper of those
    fits = [x for x in (even, start) if abs(_closing_residual(x, closing)) <= cfg.closing_tolerance_deg]
    return min(fits or [even, start], key=lambda x: x.cost)


def _closing_residual(sol: GraphSolution, closing: Edge) -> float:
    """How far (deg) the solution puts the closing pair from where its search found it."""
    q = [k for k, e in enumerate(sol.edges) if e is closing]
    return sol.residual[q[0]] if q else float("inf")


def partial_turn(chain: list[float], closing: Edge, cfg: TurnGraphConfig) -> str:
    """Why the sequence is a partial turn whose last view still overlaps the first, or "" when it is not.

    The closing pair measures the turn from the last view back to the first. When the turns as they are
    (``chain``, not wrapped) put the last view within half a turn of the first and the closing pair finds it
    right there (within ``closing_tolerance_deg``), the views simply span that much: the object did not come
    back to its start. A full turn would need the chain to be wrong by a whole turn, and solving it as one
    loads the missing turn onto a few pairs (a box's look-alike sides make that fit). A full turn's chain
    ends near +-360 minus one step, so its closing pair is never explained this way."""
    span = float(np.sum(chain))
    if abs(span) >= 180.0:
        return ""
    off = closing.best + span  # the closing pair measures minus the span when the views simply span it
    if abs(off) > cfg.closing_tolerance_deg:
        return ""
    return (f"the last view matches the first at {closing.best:+.0f} deg, where the turns put it "
            f"({-span:+.0f} deg): a partial turn of {span:+.0f} deg, not a full one")


def open_direction_sign(direction: str, open_direction: str | None, edges: list[Edge]) -> int:
    """The sign of an open sequence's turns: the given direction, else the caller's, else the estimates'."""
    if direction in ("ccw", "cw"):
        return 1 if direction == "ccw" else -1
    if open_direction in ("ccw", "cw"):
        return 1 if open_direction == "ccw" else -1
    return _open_sign(edges)


def _open_sign(edges: list[Edge]) -> int:
    """Direction of an open sequence from its neighbour estimates (their median's sign)."""
    vals = [e.best for e in edges if e.j == e.i + 1]
    return 1 if not vals or float(np.median(vals)) >= 0 else -1
