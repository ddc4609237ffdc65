"""Top level of the dynamic stage: 12 isolated views in, one colored model out.

``build_model(views, config, map_pairs=None, progress=None) -> RegisteredModel``

1. pre-process (pre-rotate by the commanded turn, stack on the centres, quantise colors; regions
   when a configuration needs them),
2. for each configuration to try: make the 12 pair jobs and hand them to ``map_pairs`` (default:
   sequential in this process; the registration service passes one that spreads them over its
   workers), combine (pose graph by default, or the paper's drop-and-chain), measure consistency; the
   first configuration alone, then (when the staged choice does not stop there) the others together
   (``run_configurations``: their pairs in shared rounds, so workers run them in parallel),
3. choose the configuration (fixed, or automatic), fuse the views at ``model_voxel`` in the ``base``
   coordinates of view 0.

Pair results computed earlier (the incremental model, ``early_pair_jobs``) are reused by fingerprint.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import open3d as o3d

from common.atomic import atomic_write_with
from services.registration.cloud import to_o3d
from services.registration.dynamic.combine import (
    CombineConfig,
    chain_poses,
    combine_paper,
    loop_closure_error,
    pairwise_consistency,
    unmeasured_gaps,
)
from services.registration.dynamic.configurations import (
    CONFIGURATIONS,
    AcceptCriteria,
    ConfigurationOutcome,
    choose,
    consistency_score,
    shortfalls,
)
from services.registration.dynamic.outliers import (
    OutlierConfig,
    handle_outlier_views,
    implausible_edges,
)
from services.registration.dynamic.pair import PairConfig, PairJob, PairResult, job_fingerprint, register_pair
from services.registration.dynamic.preprocess import (
    Cloud,
    Prepared,
    PreparedView,
    PreprocessConfig,
    attach_regions,
    edge_region_pairs,
    neighbour_edges,
    prepare_view,
    preprocess,
    scan_palette,
    stacking_frame,
    view_regions,
)
from services.registration.dynamic.turns import check_turns
from services.registration.dynamic.view_graph import optimise_pose_graph
from services.registration.dynamic.views import DynamicRegistrationError, DynamicView

MapPairs = Callable[[list[PairJob]], list[PairResult]]
Progress = Callable[[str, dict], None]


@dataclass(frozen=True)
class DynamicConfig:
    """Everything the dynamic stage can be told; the defaults are the fast, autonomous pipeline.

    ``configuration``: "auto" or one of ``CONFIGURATIONS`` (no_region, no_region_crop, region,
    region_crop). ``auto_strategy``: "staged" (cheapest first, stop when consistent) or "all".
    """

    configuration: str = "auto"
    auto_strategy: str = "staged"
    pair: PairConfig = field(default_factory=PairConfig)
    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    combine: CombineConfig = field(default_factory=CombineConfig)
    accept: AcceptCriteria = field(default_factory=AcceptCriteria)
    outliers: OutlierConfig = field(default_factory=OutlierConfig)
    model_voxel: float = 0.001

    @classmethod
    def paper(cls, configuration: str = "no_region", **pair_overrides) -> DynamicConfig:
        """The paper's procedure: paper pair mode and the drop-lowest-fitness chain."""
        return cls(configuration=configuration, pair=PairConfig(mode="paper", **pair_overrides),
                   combine=CombineConfig(method="paper"))


@dataclass
class RegisteredModel:
    """The model and everything needed to judge it without ground truth.

    ``xyz``/``rgb``/``normals`` are in the ``base`` coordinates of view 0. ``T_model_view[k]`` maps
    view k's ``base`` points into the model.
    """

    xyz: np.ndarray
    rgb: np.ndarray
    normals: np.ndarray
    T_model_view: list[np.ndarray]
    edges: list[PairResult]
    loop_closure: dict
    consistency: dict
    configuration: str
    reason: str
    combine_method: str
    dropped_edge: int | None
    candidates: dict
    timings: dict
    voxel: float
    accepted: bool = True
    why: str = ""  # the acceptance criteria the model misses, in words (empty when accepted)
    outliers: dict = field(default_factory=dict)  # the disagreeing-view check (outliers.py)
    views_left_out: list[int] = field(default_factory=list)  # view indices not fused into the model

    def __len__(self) -> int:
        return int(self.xyz.shape[0])

    def to_o3d(self) -> o3d.geometry.PointCloud:
        return to_o3d(self.xyz, self.rgb, self.normals)

    def write_ply(self, path: str | Path) -> Path:
        """Binary PLY with colors and normals, written atomically: a reader sees the old model or this one."""
        path = Path(path)
        try:
            atomic_write_with(path, lambda tmp: o3d.io.write_point_cloud(str(tmp), self.to_o3d(), write_ascii=False))
        except OSError as exc:
            raise DynamicRegistrationError("could not write model PLY", code="io_error",
                                           detail={"path": str(path), "error": str(exc)}) from None
        return path

    def to_json(self) -> dict:
        """JSON-able report: configuration and why, per-edge figures, loop closure, timings."""
        return {
            "accepted": self.accepted,
            "why": self.why,
            "configuration": self.configuration,
            "reason": self.reason,
            "views_left_out": list(self.views_left_out),
            "outlier_views": self.outliers,
            "combine": self.combine_method,
            "dropped_edge": self.dropped_edge,
            "points": len(self),
            "voxel_mm": 1000.0 * self.voxel,
            "loop_closure": self.loop_closure,
            "consistency": self.consistency,
            "edges": [e.to_json() | {"detail": {}} for e in self.edges],
            "T_model_view": [np.asarray(T).tolist() for T in self.T_model_view],
            "candidates": self.candidates,
            "timings": self.timings,
        }

    def dumps(self) -> str:
        return json.dumps(self.to_json(), indent=2, default=float)


def sequential_map(jobs: list[PairJob]) -> list[PairResult]:
    """Default ``map_pairs``: run every job here, in order."""
    return [register_pair(j) for j in jobs]


def process_pool_map(workers: int) -> MapPairs:
    """A ``map_pairs`` that runs jobs in ``workers`` local processes: offline use of one machine's cores."""
    def run(jobs: list[PairJob]) -> list[PairResult]:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            return list(pool.map(register_pair, jobs))

    return run


def pair_job(index: int, vs: PreparedView, vt: PreparedView, center: np.ndarray, axis: np.ndarray,
             pair: PairConfig, region_pairs: list[tuple[int, int]] | None = None) -> PairJob:
    """Edge ``index``: register prepared view ``vs`` onto ``vt`` (the one place a pair job is built)."""
    return PairJob(
        index=index, source_view=vs.index, target_view=vt.index, source=vs.reduced, target=vt.reduced,
        center=center, axis=axis, config=replace(pair, seed=pair.seed + 1000 * index),
        source_regions=vs.regions if pair.regions else [], target_regions=vt.regions if pair.regions else [],
        region_pairs=(region_pairs or []) if pair.regions else [])


def make_pair_jobs(prep: Prepared, pair: PairConfig) -> list[PairJob]:
    """The 12 neighbour pair jobs (view i+1 onto view i, and the 0 onto n-1 loop closure)."""
    return [pair_job(k, prep.views[s], prep.views[t], prep.center, prep.axis, pair, prep.region_pairs.get((s, t)))
            for k, (s, t) in enumerate(neighbour_edges(len(prep.views)))]


def configuration_names(config: DynamicConfig) -> list[str]:
    """The configurations ``build_model`` runs, in order (the automatic choice: cheapest first)."""
    if config.configuration == "auto":
        return list(CONFIGURATIONS)
    if config.configuration in CONFIGURATIONS:
        return [config.configuration]
    raise DynamicRegistrationError(f"unknown configuration {config.configuration!r}", code="bad_value",
                                   detail={"configurations": ["auto", *CONFIGURATIONS]})


def early_pair_jobs(views: dict[int, DynamicView], source: int, config: DynamicConfig,
                    names: list[str] | None = None) -> list[tuple[str, PairJob]]:
    """The jobs ``build_model`` may run for edge ``source`` -> ``source - 1``, from the views so far: one per
    configuration it may run (or per name of ``names``), as (name, job) in ``configuration_names`` order.

    For the incremental model: while later views are still being captured, these jobs are already final when
    the palette comes from the first views only (``preprocess.palette_views``). A region configuration's job
    is final too: ``view_regions`` segments each view on its own (fixed seed) and ``edge_region_pairs`` pairs
    the edge's two views by GOOD, so the regions and region pairs here are those ``attach_regions`` finds at
    the end, and the job has the same fingerprint. ``views`` must hold view 0, the palette's views,
    ``source`` and ``source - 1``; empty when the jobs cannot be known yet (the caller leaves them to the end).
    """
    pre = config.preprocess
    if source < 1 or pre.palette_views < 1 or source < pre.palette_views - 1:
        return []
    needed = {0, source - 1, source, *range(pre.palette_views)}
    if not needed <= set(views):
        return []
    names = [n for n in configuration_names(config) if names is None or n in names]
    if not names:
        return []
    center, axis = stacking_frame(views[0])
    palette = scan_palette([views[k] for k in range(pre.palette_views)], pre)
    for k in (source - 1, source):
        views[k].validate()
    vs, vt = (prepare_view(views[k], center, axis, palette, pre) for k in (source, source - 1))
    jobs = []
    for name in names:
        regions, crop = CONFIGURATIONS[name]
        region_pairs = None
        if regions:
            if not vs.regions and not vt.regions:  # once per edge, shared by the region configurations
                vs.regions, vt.regions = view_regions(vs, pre), view_regions(vt, pre)
            region_pairs = edge_region_pairs(vs, vt, pre)
        jobs.append((name, pair_job(source - 1, vs, vt, center, axis, replace(config.pair, regions=regions, crop=crop),
                                    region_pairs)))
    return jobs


def early_pair_job(views: dict[int, DynamicView], source: int, config: DynamicConfig,
                   configuration: str | None = None) -> PairJob | None:
    """One of ``early_pair_jobs``: the named configuration's (default: the first one ``build_model`` runs);
    None when it cannot be known yet, or when ``build_model`` would not run that configuration."""
    name = configuration or configuration_names(config)[0]
    if name not in CONFIGURATIONS:
        raise DynamicRegistrationError(f"unknown configuration {name!r}", code="bad_value",
                                       detail={"configurations": sorted(CONFIGURATIONS)})
    jobs = early_pair_jobs(views, source, config, [name])
    return jobs[0][1] if jobs else None


def reusing(map_pairs: MapPairs, reuse: dict[str, PairResult], stats: dict) -> MapPairs:
    """A ``map_pairs`` that answers a job from ``reuse`` (fingerprint -> result) when it holds that exact job.

    Results are matched to jobs by position: one call may carry several configurations' jobs of the same edge
    index (``run_configurations``)."""
    def run(jobs: list[PairJob]) -> list[PairResult]:
        known = [reuse.get(job_fingerprint(j)) if reuse else None for j in jobs]
        todo = [j for j, k in zip(jobs, known, strict=True) if k is None]
        fresh = iter(map_pairs(todo) if todo else [])
        stats["reused"] = stats.get("reused", 0) + len(jobs) - len(todo)
        stats["computed"] = stats.get("computed", 0) + len(todo)
        return [k if k is not None else next(fresh) for k in known]

    return run


def chain_to_first(results: list[PairResult]) -> np.ndarray:
    """T mapping view n-1 onto view 0 by composing the neighbour results (each maps view i+1 onto view i)."""
    T = np.eye(4)
    for r in sorted(results, key=lambda r: r.source_view):
        T = T @ np.asarray(r.T)
    return T


def run_configuration(prep: Prepared, name: str, config: DynamicConfig, map_pairs: MapPairs) -> ConfigurationOutcome:
    """Pairs + combination + consistency for one named configuration."""
    return run_configurations(prep, [name], config, map_pairs)[0]


def run_configurations(prep: Prepared, names: list[str], config: DynamicConfig,
                       map_pairs: MapPairs) -> list[ConfigurationOutcome]:
    """Pairs + combination + consistency for several configurations at once, in two rounds of ``map_pairs``:
    every configuration's neighbour pairs in one call, then every loop closure in one call.

    Why together: after the first configuration is rejected the automatic choice runs all the others anyway, and
    what is left of each (its last neighbour edge, its loop closure, when the incremental model computed the
    rest during the acquisition) is a few independent jobs; one call lets the workers run them in parallel
    instead of one configuration after another. The outcomes are those of running the configurations one by
    one: each job is a function of itself alone (its fingerprint), whatever worker runs it and in whatever
    order. ``seconds`` of each outcome counts the shared pair rounds plus its own combination.
    """
    for name in names:
        if name not in CONFIGURATIONS:
            raise DynamicRegistrationError(f"unknown configuration {name!r}", code="bad_value",
                                           detail={"configurations": sorted(CONFIGURATIONS)})
    t0 = time.perf_counter()
    if any(CONFIGURATIONS[name][0] for name in names):
        attach_regions(prep, config.preprocess)
    jobs = {name: make_pair_jobs(prep, replace(config.pair, regions=CONFIGURATIONS[name][0],
                                               crop=CONFIGURATIONS[name][1])) for name in names}
    # Neighbour pairs first; the loop-closure pair (view 0 onto view n-1) then starts from the chain of their
    # measured transforms, not from the commanded turns: a systematic turn error (the robot-turned profile's
    # gain: 26-44 degrees achieved per commanded 30) accumulates to tens of degrees by the last view, beyond
    # what the local search recovers, while each neighbour pair is off by only a few degrees.
    neighbours = [j for name in names for j in jobs[name][:-1]]
    flat = map_pairs(neighbours)
    if len(flat) != len(neighbours):
        raise DynamicRegistrationError("map_pairs returned the wrong number of results", code="bad_workers",
                                       detail={"jobs": len(neighbours), "results": len(flat)})
    results: dict[str, list[PairResult]] = {}
    for i, name in enumerate(names):
        n = len(jobs[name]) - 1
        results[name] = sorted(flat[i * n:(i + 1) * n], key=lambda r: r.index)
        loop_job = jobs[name][-1]
        loop_job.prior = np.linalg.inv(chain_to_first(results[name])) if results[name] else loop_job.prior
    loops = map_pairs([jobs[name][-1] for name in names])
    if len(loops) != len(names):
        raise DynamicRegistrationError("map_pairs returned the wrong number of results", code="bad_workers",
                                       detail={"jobs": len(names), "results": len(loops)})
    t_pairs = time.perf_counter() - t0
    outcomes = []
    for name, loop in zip(names, loops, strict=True):
        t1 = time.perf_counter()
        outcome = _finish_configuration(prep, name, config, results[name] + [loop])
        outcome.seconds = t_pairs + time.perf_counter() - t1
        outcome.extra = {"pairs_seconds": t_pairs}
        outcomes.append(outcome)
    return outcomes


def _finish_configuration(prep: Prepared, name: str, config: DynamicConfig,
                          results: list[PairResult]) -> ConfigurationOutcome:
    """Combination, loop closure, the disagreeing-view check and consistency of one configuration's pairs.

    An edge whose correction the turn accuracy cannot explain is kept out of the combination (when the other
    edges still connect every view); the posed fitness then judges it. Views that disagree with the others
    are re-registered or left out (``outliers.py``); the consistency figures are those of the views kept.
    """
    oc = config.outliers
    implausible = implausible_edges(results, oc) if oc.enabled else []
    combine_on = _without_edges(len(prep.views), results, {e["edge"] for e in implausible})
    if config.combine.method == "pose_graph":
        combined = optimise_pose_graph(prep, combine_on, config.combine)
    elif config.combine.method == "paper":
        combined = combine_paper(prep, combine_on, config.combine)
    else:
        raise DynamicRegistrationError(f"unknown combine method {config.combine.method!r}", code="bad_value")
    loop = loop_closure_error(results, prep.center)
    handled = handle_outlier_views(prep, combined.poses, results, oc, implausible) if oc.enabled else None
    judged = results
    if handled is not None:
        combined.poses = handled.poses
        left = handled.left_out_positions
        judged = [r for r in results if r.source_view not in left and r.target_view not in left] or results
    consistency = pairwise_consistency(prep, combined.poses, judged, config.combine)
    if len(judged) != len(results):
        consistency["edges"] = [r.index for r in judged]
    left_out = handled.left_out_positions if handled is not None else set()
    kept = [k for k in range(len(prep.views)) if k not in left_out]
    if handled is not None and (handled.outliers or handled.implausible_edges):  # the loop no longer judges
        kept_edges = [r for r in combine_on if r.source_view not in left_out and r.target_view not in left_out]
        consistency["unmeasured_gaps"] = unmeasured_gaps(prep, combined.poses, kept_edges, kept, config.combine)
    turns = check_turns(combined.poses, prep.axis, kept,
                        oc.turn_sigma_deg, config.accept.turn_sigmas, [v.index for v in prep.views])
    consistency["turns"] = turns.to_json()
    out = ConfigurationOutcome(name, results, combined, loop, consistency, 0.0, outliers=handled, turns=turns)
    out.score = consistency_score(loop, consistency, handled)
    return out


def _without_edges(n_views: int, results: list[PairResult], drop: set[int]) -> list[PairResult]:
    """``results`` without the ``drop`` edges, or all of them when the rest would not connect every view."""
    if not drop:
        return results
    kept = [r for r in results if r.index not in drop]
    try:
        chain_poses(n_views, kept)
    except DynamicRegistrationError:
        return results
    return kept


def fuse(views: list[DynamicView], T_model_view: list[np.ndarray], voxel: float) -> Cloud:
    """All views in the model frame, merged on a ``voxel`` grid (colors and normals averaged)."""
    pcd = o3d.geometry.PointCloud()
    for v, T in zip(views, T_model_view, strict=True):
        nrm = v.normals if v.normals is not None else np.zeros_like(v.xyz)
        pcd += Cloud(np.asarray(v.xyz, np.float32), np.asarray(v.rgb, np.uint8),
                     np.asarray(nrm, np.float32)).transformed(T).to_o3d()
    if voxel > 0:
        pcd = pcd.voxel_down_sample(voxel)
    if any(v.normals is None for v in views):
        pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=max(4 * voxel, 0.004), max_nn=30))
    return Cloud.from_o3d(pcd)


def build_model(views: list[DynamicView], config: DynamicConfig | None = None,
                map_pairs: MapPairs | None = None, progress: Progress | None = None,
                reuse: dict[str, PairResult] | None = None) -> RegisteredModel:
    """Register the views into one colored model; see the module doc.

    ``reuse`` (job fingerprint -> result): pair results computed earlier, e.g. during the acquisition;
    a job whose fingerprint is there is not run again (``timings["pairs"]`` counts reused and computed).
    """
    cfg = config or DynamicConfig()
    pair_stats: dict = {"reused": 0, "computed": 0}
    run = reusing(map_pairs or sequential_map, reuse or {}, pair_stats)
    say = progress or (lambda stage, info: None)
    t0 = time.perf_counter()
    prep = preprocess(views, cfg.preprocess)
    say("preprocessed", {"views": len(views), "seconds": prep.seconds})
    names = configuration_names(cfg)
    staged = cfg.configuration == "auto" and cfg.auto_strategy == "staged"
    outcomes = run_configurations(prep, names[:1], cfg, run)
    say("configuration", {"name": names[0], **outcomes[0].summary()})
    if len(names) > 1 and not (staged and choose(outcomes, cfg.accept, True)[1].startswith("first")):
        # the first is rejected (or every configuration is wanted): the rest all run, together
        for outcome in run_configurations(prep, names[1:], cfg, run):
            outcomes.append(outcome)
            say("configuration", {"name": outcome.name, **outcome.summary()})
    if len(outcomes) == 1 and cfg.configuration != "auto":
        chosen, reason = outcomes[0], f"fixed by configuration ({cfg.configuration})"
    else:
        chosen, reason = choose(outcomes, cfg.accept, staged)
    misses = shortfalls(chosen, cfg.accept)
    t_fuse = time.perf_counter()
    T_model_view = [P @ pv.T_stack_view for P, pv in zip(chosen.combined.poses, prep.views, strict=True)]
    left = chosen.outliers.left_out_positions if chosen.outliers is not None else set()
    fused = [k for k in range(len(views)) if k not in left]
    model = fuse([views[k] for k in fused], [T_model_view[k] for k in fused], cfg.model_voxel)
    timings = {"preprocess_s": prep.seconds,
               **{f"{o.name}_s": o.seconds for o in outcomes},
               "fuse_s": time.perf_counter() - t_fuse, "total_s": time.perf_counter() - t0,
               "pairs": pair_stats}
    say("done", {"configuration": chosen.name, "seconds": timings["total_s"]})
    return RegisteredModel(model.xyz, model.rgb, model.normals, T_model_view, chosen.results, chosen.loop,
                           chosen.consistency, chosen.name, reason, chosen.combined.method,
                           chosen.combined.dropped_edge, {o.name: o.summary() for o in outcomes}, timings,
                           cfg.model_voxel, accepted=not misses, why="; ".join(misses),
                           outliers=chosen.outliers.to_json() if chosen.outliers is not None else {},
                           views_left_out=[views[k].index for k in sorted(left)])
