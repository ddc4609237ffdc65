"""The paper's four configurations and the automatic choice among them (beyond the paper).

The paper compares regions on/off x crop (favour overlap) on/off, finds no clear winner and leaves the
choice to a person ("run all four and choose the alignment with the highest fitness"). Here the
choice is made from figures the pipeline can compute without ground truth:

* the loop-closure error of the 12 pair transforms (rotation, and displacement of the object centre):
  if every pair is right their composition around the loop is the identity, so a wrong pair shows;
* the fitness of every neighbour pair *as posed in the final model* (including the loop edge), which
  sees a misplaced view whatever the pair stage claimed.

``consistency_score`` folds them into one number (higher is better). The ``staged`` strategy runs
the configurations cheapest first and stops at the first whose loop closes and whose posed fitness
is high; ``all`` runs all four and takes the best score. Either way the reason is reported.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from services.registration.dynamic.combine import CombineResult
from services.registration.dynamic.pair import PairResult

if TYPE_CHECKING:
    from services.registration.dynamic.outliers import OutlierOutcome
    from services.registration.dynamic.turns import TurnCheck

# name -> (regions, crop), cheapest first (the staged order)
CONFIGURATIONS: dict[str, tuple[bool, bool]] = {
    "no_region": (False, False),
    "no_region_crop": (False, True),
    "region": (True, False),
    "region_crop": (True, True),
}


@dataclass(frozen=True)
class AcceptCriteria:
    """When the staged choice may stop: the loop closes and every neighbour fits as posed."""

    max_loop_rotation_deg: float = 5.0  # 12 edges of ~0.5-1° error each add up to a few degrees
    max_loop_translation_mm: float = 5.0  # an arm's scan (12 views); a fixed camera's: from its noise, below
    # Judge the loop's displacement against the session's own noise instead of ``max_loop_translation_mm``
    # (``loop_translation_gate_mm``; None: the session decides, ``api.session_dynamic_config``: a fixed camera
    # does). Its sequences run 8-24 pairs of a sensor whose noise grows with the square of the distance
    # (a D415 at 0.4 m, a PrimeSense at 1 m: 1.4-1.6 mm of posed RMSE), which one millimetre figure cannot hold.
    loop_translation_from_noise: bool | None = None
    loop_noise_sigmas: float = 3.0  # a loop open by more than this many random-walk sigmas is a wrong pair
    min_posed_fitness: float = 0.6
    # a view left out opens a 60-degree gap; two still leave every side seen, more is not a full model
    max_views_left_out: int = 2
    # each turn in the model within this many sigmas of the session's turn accuracy (turns.py)
    turn_sigmas: float = 5.0
    # Judge each posed neighbour pair on its overlap instead of all its points (None: the session decides,
    # ``api.session_dynamic_config``: a fixed camera does). A camera looking at the object from the side sees one
    # or two faces per view, and where a corner turns past, half of a view lies on a face its neighbour never
    # sees: posed fitness then measures the overlap (0.35-0.6 on correct models), not the alignment. An arm
    # looking down sees the top in every view, so all its points are compared.
    judge_overlap: bool | None = None
    # over the overlap: the share of a pair's shared points within the consistency distance (the same
    # notion as a view agreeing with the others), and the least overlap that can vouch for a pair at all
    min_posed_agreement: float = 0.8
    min_posed_overlap: float = 0.25


@dataclass
class ConfigurationOutcome:
    """One configuration run end to end (pairs + combination) and its self-assessed figures."""

    name: str
    results: list[PairResult]
    combined: CombineResult
    loop: dict
    consistency: dict
    seconds: float
    score: float = 0.0
    extra: dict = field(default_factory=dict)
    outliers: OutlierOutcome | None = None  # the disagreeing-view check (outliers.py), when it ran
    turns: TurnCheck | None = None  # do the views turn as commanded (turns.py)

    @property
    def loop_waived(self) -> bool:
        """The loop composition runs through an edge or a view that was set aside: it cannot judge the poses,
        the posed fitness of every edge (and each view against the others) does."""
        o = self.outliers
        return o is not None and bool(o.outliers or o.implausible_edges)

    def summary(self) -> dict:
        return {"score": self.score, "loop_rotation_deg": self.loop["rotation_deg"],
                "loop_translation_mm": self.loop["translation_mm"],
                "mean_pair_fitness": sum(r.fitness for r in self.results) / len(self.results),
                "mean_posed_fitness": self.consistency["mean_posed_fitness"],
                "min_posed_fitness": self.consistency["min_posed_fitness"],
                "mean_posed_rmse_mm": self.consistency["mean_posed_rmse_mm"],
                "combine": self.combined.method, "dropped_edge": self.combined.dropped_edge,
                "views_left_out": [d["view"] for d in self.outliers.left_out] if self.outliers else [],
                "paths": [r.path for r in self.results], "seconds": self.seconds}


def consistency_score(loop: dict, consistency: dict, outliers: OutlierOutcome | None = None) -> float:
    """Higher is better: posed fitness (mean and worst) minus loop-closure penalties.

    Scale: 1° of loop rotation or 5 mm of loop displacement costs as much as 0.02 of fitness. When the loop
    runs through an edge or view set aside (``ConfigurationOutcome.loop_waived``) it is not counted; each
    view left out costs 0.1 instead (a model with every view is preferred when it is as consistent).
    """
    waived = outliers is not None and bool(outliers.outliers or outliers.implausible_edges)
    rot = loop["rotation_deg"] if loop["rotation_deg"] == loop["rotation_deg"] else 180.0
    trans = loop["translation_mm"] if loop["translation_mm"] == loop["translation_mm"] else 1000.0
    penalty = 0.1 * len(outliers.left_out) if waived else 0.02 * rot + 0.004 * trans
    return 0.5 * consistency["mean_posed_fitness"] + 0.5 * consistency["min_posed_fitness"] - penalty


def loop_translation_gate_mm(outcome: ConfigurationOutcome, criteria: AcceptCriteria) -> float:
    """The largest loop displacement (mm) that noise explains, or the fixed gate when not judged on noise.

    Why this figure: each pair places its source view on its target to within the point noise the two
    show once posed (their inlier RMSE: the sensor's noise at that distance, as the session measures it,
    the median over the loop's pairs so one bad pair cannot widen it). ``n`` pairs composed around the loop
    add such independent errors as a random walk, ``sqrt(n)`` x noise; beyond ``loop_noise_sigmas`` of that
    the loop is open by more than noise, i.e. a pair is wrong. The pose graph then spreads what is left over
    the ``n`` edges, a fraction of the noise each.
    """
    if not criteria.loop_translation_from_noise:
        return criteria.max_loop_translation_mm
    rmse = [x for x in outcome.consistency.get("posed_rmse_mm") or [] if math.isfinite(x)]
    if not rmse or not getattr(outcome, "results", None):  # no per-pair figures (a summary): the fixed gate
        return criteria.max_loop_translation_mm
    return criteria.loop_noise_sigmas * math.sqrt(len(outcome.results)) * statistics.median(rmse)


def acceptable(outcome: ConfigurationOutcome, criteria: AcceptCriteria) -> bool:
    return not shortfalls(outcome, criteria)


def shortfalls(outcome: ConfigurationOutcome, criteria: AcceptCriteria) -> list[str]:
    """Which acceptance criteria ``outcome`` misses, in words (empty: accepted).

    This is the ``why`` of an unaccepted model: a person reading the report sees which figure failed.
    A NaN loop figure (a loop that could not be composed) fails its criterion.
    """
    out = []
    rot, trans = outcome.loop["rotation_deg"], outcome.loop["translation_mm"]
    if not outcome.loop_waived:
        if not rot <= criteria.max_loop_rotation_deg:
            out.append(f"loop closure {rot:.2f} deg > {criteria.max_loop_rotation_deg:g} deg")
        gate = loop_translation_gate_mm(outcome, criteria)
        if not trans <= gate:
            noise = " (the noise's random walk over the loop)" if criteria.loop_translation_from_noise else ""
            out.append(f"loop closure {trans:.1f} mm > {gate:.3g} mm{noise}")
    else:
        o = outcome.outliers
        if o.no_majority:
            out.append(f"no two views agree ({len(o.outliers)} of {len(o.fitness)} fail the outlier test): "
                       "the wrong ones cannot be told from the rest")
        left = [d["view"] for d in o.left_out]
        if len(left) > criteria.max_views_left_out:
            out.append(f"{len(left)} views left out ({left}) > {criteria.max_views_left_out}")
        kept = [f for f in o.fitness if f == f]
        if kept and min(kept) < criteria.min_posed_fitness:
            out.append(f"a kept view fits the others at {min(kept):.3f} < {criteria.min_posed_fitness:g}")
        gaps = [g for g in outcome.consistency.get("unmeasured_gaps", []) if g["overlap"] < criteria.min_posed_overlap]
        if gaps:  # the loop was waived and nothing else measured these turns (combine.unmeasured_gaps)
            where = ", ".join(f"{g['from']} -> {g['to']} (overlap {g['overlap']:.2f})" for g in gaps)
            out.append(f"the turn between kept views {where} is not measured: no kept pair links them and they "
                       f"share under {criteria.min_posed_overlap:g}; only the loop's full turn places them")
    if outcome.turns is not None:  # whatever else was waived: stacked views fit each other and close the loop
        out.extend(outcome.turns.misses)
    c = outcome.consistency
    if criteria.judge_overlap and "posed_agreement" in c:
        _posed_shortfall(out, c, "posed_agreement", criteria.min_posed_agreement, "posed agreement over the overlap")
        _posed_shortfall(out, c, "posed_overlap", criteria.min_posed_overlap, "posed overlap")
    else:
        _posed_shortfall(out, c, "posed_fitness", criteria.min_posed_fitness, "posed fitness")
    return out


def _posed_shortfall(out: list[str], consistency: dict, key: str, least: float, words: str) -> None:
    """Append why the worst edge's ``key`` (a per-edge figure of ``pairwise_consistency``) is below ``least``."""
    fits = consistency.get(key) or []
    # without the per-edge figures (a summary, e.g. a model recorded before they were kept) judge the minimum
    worst = min(fits) if fits else float(consistency.get(f"min_{key}", float("nan")))
    if not worst >= least:
        names = consistency.get("edges") or list(range(len(fits)))  # edge indices when some were left out
        edge = names[int(min(range(len(fits)), key=lambda i: fits[i]))] if fits else None
        where = f" (edge {edge})" if edge is not None else ""
        out.append(f"{words} {worst:.3f}{where} < {least:g}")


def describe(outcome: ConfigurationOutcome) -> str:
    return (f"{outcome.name}: loop {outcome.loop['rotation_deg']:.2f}° / {outcome.loop['translation_mm']:.1f} mm, "
            f"posed fitness mean {outcome.consistency['mean_posed_fitness']:.3f} "
            f"min {outcome.consistency['min_posed_fitness']:.3f}, score {outcome.score:.3f}")


def choose(outcomes: list[ConfigurationOutcome], criteria: AcceptCriteria,
           staged: bool) -> tuple[ConfigurationOutcome, str]:
    """Pick the configuration to keep and say why."""
    if staged and len(outcomes) == 1 and acceptable(outcomes[0], criteria):
        return outcomes[0], f"first configuration consistent, stopped there ({describe(outcomes[0])})"
    best = max(outcomes, key=lambda o: o.score)
    others = "; ".join(describe(o) for o in outcomes if o is not best)
    verdict = "consistent" if acceptable(best, criteria) else "best available, NOT within acceptance"
    return best, f"highest consistency score, {verdict} ({describe(best)}); others: {others or 'none'}"
