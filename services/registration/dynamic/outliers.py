"""A view that disagrees with the model: found, re-registered once from the others, else left out.

Why: one wrong view (a scan fused with a wrong pose upstream, a cloud from the wrong turn) makes a model
that is wrong everywhere that view covers, while the other eleven agree with each other. The pair edges and
the loop closure see it only indirectly; the views' *posed* clouds see it directly:

* **consensus fitness**: each view's posed cloud against the union of all the other posed views. Every
  surface point of a 12-view scan is seen by several views, so a well-placed view finds most of its points
  on the others; a misplaced or corrupted one does not.
* **a robust outlier test** over those twelve figures: a view is an outlier when it lies more than
  ``robust_k`` robust standard deviations (1.4826 x MAD) *and* ``misfit_ratio`` times the median misfit
  away (misfit = 1 - fitness), above a small noise floor. Both are relative to this object's own views, so
  no fixed fitness number tuned to one shape decides (a thin object's views fit less than a box's, all of
  them alike).
* **turn plausibility**: a pair edge's correction (its rotation in the pre-rotated frames: the achieved turn
  minus the commanded one) beyond ``turn_window_deg`` is not a turn error the turntable-by-hand or the arm
  can make (a symmetric box matches itself turned by 90 degrees). Such an edge is kept out of the pose
  graph when the other edges still connect every view, and a view whose two edges are both implausible is
  treated as an outlier whatever its fitness.

An outlier view is registered once more, against the consensus of the others (point-to-plane ICP from its
neighbours' poses, which carry the commanded turn), and kept when it then passes the same test with a
plausible pose; otherwise it is left out of the model. Dropping one of 12 views at 30 degrees leaves a
60-degree gap between its neighbours; those are still placed by the pose graph through the rest of the loop.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from common.geometry import invert, rotation_angle_deg
from services.registration.dynamic.pair import PairResult
from services.registration.dynamic.preprocess import Cloud, Prepared

reg = o3d.pipelines.registration

#: Default 1-sigma accuracy of a turn (degrees) when the session does not state one: the twin's robot-turned
#: profile reaches 26-44 degrees per commanded 30 plus a 4-degree scatter, so 6 degrees x 5 = 30 keeps every
#: real turn error and still rejects a 90-degree flip of a symmetric object.
DEFAULT_TURN_SIGMA_DEG = 6.0


@dataclass(frozen=True)
class OutlierConfig:
    """How a disagreeing view is found and handled (see the module doc)."""

    enabled: bool = True
    voxel: float = 0.003  # posed clouds are compared at this voxel
    distance: float = 0.003  # a point is on the consensus within this distance
    robust_k: float = 3.5  # robust z-score of the misfit (1 - fitness) above the median that makes an outlier
    misfit_ratio: float = 3.0  # ... and at least this many times the median misfit
    min_misfit: float = 0.03  # ... and above this noise floor (3 % of a view's points off the others)
    turn_sigma_deg: float = DEFAULT_TURN_SIGMA_DEG  # the session's stated turn accuracy (1 sigma)
    turn_window_sigmas: float = 5.0  # corrections beyond this many sigmas are implausible
    icp_max_correspondence: tuple[float, ...] = (0.008, 0.004, 0.002)

    @property
    def turn_window_deg(self) -> float:
        return self.turn_window_sigmas * self.turn_sigma_deg


@dataclass
class OutlierOutcome:
    """Poses after handling, and what was found: per-view consensus fitness, the test's figures, who moved."""

    poses: list[np.ndarray]
    fitness: list[float]
    threshold: float
    outliers: list[int] = field(default_factory=list)  # positions in ``prep.views`` flagged by the test
    reregistered: list[dict] = field(default_factory=list)
    left_out: list[dict] = field(default_factory=list)
    implausible_edges: list[dict] = field(default_factory=list)
    # fewer than two views passed the test: which ones are wrong cannot be told, so none is left out and the
    # model is not accepted (``configurations.shortfalls``)
    no_majority: bool = False

    @property
    def left_out_positions(self) -> set[int]:
        return {d["position"] for d in self.left_out}

    def to_json(self) -> dict:
        fitness = [None if f != f else round(float(f), 4) for f in self.fitness]  # None: left out (JSON has no NaN)
        return {"consensus_fitness": fitness, "threshold": round(self.threshold, 4),
                "outliers": list(self.outliers), "reregistered": self.reregistered, "left_out": self.left_out,
                "implausible_edges": self.implausible_edges, "no_majority": self.no_majority}


def edge_correction_deg(result: PairResult) -> float:
    """How far a pair's turn is from the commanded one: its rotation in the pre-rotated frames (degrees)."""
    return rotation_angle_deg(np.asarray(result.T)[:3, :3])


def implausible_edges(results: list[PairResult], cfg: OutlierConfig) -> list[dict]:
    """Pair edges whose correction is beyond what the turn accuracy allows (failed pairs are not judged)."""
    out = []
    for r in results:
        if r.path == "failed":
            continue
        angle = edge_correction_deg(r)
        if angle > cfg.turn_window_deg:
            out.append({"edge": r.index, "source_view": r.source_view, "target_view": r.target_view,
                        "correction_deg": round(angle, 2), "window_deg": round(cfg.turn_window_deg, 2)})
    return out


def _posed_clouds(prep: Prepared, poses: list[np.ndarray], voxel: float) -> list[Cloud]:
    return [v.reduced.downsampled(voxel).transformed(np.asarray(P)) for v, P in zip(prep.views, poses, strict=True)]


def _fitness(points: np.ndarray, tree: cKDTree, distance: float) -> float:
    if len(points) == 0 or tree.n == 0:
        return 0.0
    d, _ = tree.query(points.astype(np.float64), k=1, distance_upper_bound=distance)
    return float(np.isfinite(d).mean())


def consensus_fitness(clouds: list[Cloud], members: list[int], distance: float) -> dict[int, float]:
    """Fitness of each member's posed cloud against the union of the other members' clouds."""
    out = {}
    for k in members:
        others = [clouds[j].xyz for j in members if j != k]
        tree = cKDTree(np.vstack(others).astype(np.float64)) if others else cKDTree(np.zeros((0, 3)))
        out[k] = _fitness(clouds[k].xyz, tree, distance)
    return out


def robust_threshold(values: list[float], cfg: OutlierConfig) -> float:
    """Fitness below which a view is an outlier among ``values``.

    Judged on the misfit (1 - fitness): a view is an outlier when its misfit exceeds the median misfit by
    ``robust_k`` robust standard deviations (1.4826 x MAD), is ``misfit_ratio`` times the median misfit,
    and is above the sensor's noise floor (``min_misfit``). On clean views every misfit is near zero and
    the MAD is zero: the ratio and the floor keep a view that is 0.1 % worse than the others from being
    called an outlier, while one whose tenth of points lies off the others is.
    """
    miss = 1.0 - np.asarray(values, dtype=float)
    med = float(np.median(miss))
    mad = float(np.median(np.abs(miss - med)))
    limit = max(med + cfg.robust_k * 1.4826 * mad, cfg.misfit_ratio * med, cfg.min_misfit)
    return 1.0 - limit


def _neighbours(position: int, members: list[int]) -> list[int]:
    """The members just before and after ``position`` around the loop."""
    ring = sorted(members)
    before = [m for m in ring if m < position] or ring
    after = [m for m in ring if m > position] or ring
    return [m for m in dict.fromkeys([before[-1], after[0]]) if m != position]


def _reregister(prep: Prepared, poses: list[np.ndarray], k: int, members: list[int], clouds: list[Cloud],
                threshold: float, cfg: OutlierConfig) -> tuple[np.ndarray | None, dict]:
    """View ``k`` registered once against the union of the other members, from its neighbours' poses.

    The pre-processed frames carry the commanded turn, so a neighbour's pose is where the view would be with
    a perfect turn; ICP from there finds the turn error. Kept when the pose is plausible (within the turn
    window of that neighbour) and the view then passes the outlier test."""
    others = [j for j in members if j != k]
    if not others:  # nothing else is left to register it against: it stays out
        return None, {"tried": [], "why": "no other view to register against"}
    target = Cloud(np.vstack([clouds[j].xyz for j in others]), np.vstack([clouds[j].rgb for j in others]),
                   np.vstack([clouds[j].normals for j in others])).to_o3d()
    tree = cKDTree(np.asarray(target.points))
    source = prep.views[k].reduced.downsampled(cfg.voxel)
    src = source.to_o3d()
    best: tuple[float, np.ndarray, int] | None = None
    tried = []
    for nb in _neighbours(k, others):
        P = np.asarray(poses[nb], dtype=float).copy()
        for d in cfg.icp_max_correspondence:
            r = reg.registration_icp(src, target, d, P, reg.TransformationEstimationPointToPlane(),
                                     reg.ICPConvergenceCriteria(relative_fitness=1e-6, relative_rmse=1e-6,
                                                                max_iteration=40))
            if np.isfinite(r.transformation).all():
                P = np.asarray(r.transformation)
        correction = rotation_angle_deg((invert(np.asarray(poses[nb])) @ P)[:3, :3])
        fit = _fitness(source.transformed(P).xyz, tree, cfg.distance)
        tried.append({"from_view": prep.views[nb].index, "fitness": round(fit, 4),
                      "correction_deg": round(correction, 2)})
        if correction <= cfg.turn_window_deg and (best is None or fit > best[0]):
            best = (fit, P, nb)
    info = {"tried": tried}
    if best is None or best[0] < threshold:
        return None, info
    info["fitness"] = round(best[0], 4)
    return best[1], info


def handle_outlier_views(prep: Prepared, poses: list[np.ndarray], results: list[PairResult],
                         cfg: OutlierConfig, implausible: list[dict] | None = None) -> OutlierOutcome:
    """Find the views that disagree with the others; re-register each once, else leave it out.

    Deterministic: views are taken in index order and every figure is a function of the clouds and poses.
    """
    poses = [np.asarray(P, dtype=float) for P in poses]
    n = len(prep.views)
    members = list(range(n))
    clouds = _posed_clouds(prep, poses, cfg.voxel)
    fit = consensus_fitness(clouds, members, cfg.distance)
    threshold = robust_threshold([fit[k] for k in members], cfg)
    implausible = implausible if implausible is not None else implausible_edges(results, cfg)
    position = {v.index: i for i, v in enumerate(prep.views)}
    bad_edges = [(position.get(e["source_view"]), position.get(e["target_view"])) for e in implausible]
    both_bad = {k for k in members if sum(1 for s, t in bad_edges if k in (s, t)) >= 2}
    flagged = sorted({k for k in members if fit[k] < threshold} | both_bad)
    out = OutlierOutcome(poses, [fit[k] for k in members], threshold, flagged, implausible_edges=implausible)
    if not cfg.enabled or not flagged:
        return out
    kept = [k for k in members if k not in flagged]
    if len(kept) < 2:  # no two views agree: nothing to tell the wrong ones from
        out.no_majority = True
        return out
    for k in flagged:  # index order: the same session gives the same decisions
        pose, info = _reregister(prep, poses, k, kept + [k], clouds, threshold, cfg)
        record = {"view": prep.views[k].index, "position": k, "consensus_fitness": round(fit[k], 4),
                  "implausible_edges": k in both_bad, **info}
        if pose is not None:
            poses[k] = pose
            clouds[k] = prep.views[k].reduced.downsampled(cfg.voxel).transformed(pose)
            out.reregistered.append(record)
        else:
            out.left_out.append(record)
    final = [k for k in members if k not in out.left_out_positions]
    refit = consensus_fitness(clouds, final, cfg.distance)
    out.poses = poses
    out.fitness = [refit.get(k, float("nan")) for k in members]
    return out
