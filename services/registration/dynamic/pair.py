"""Registration of one neighbour pair (paper II-C-2), as a pure function of picklable inputs.

``register_pair(job) -> PairResult`` takes only numpy arrays and frozen dataclasses, so a pair job can
run in another process or on another machine (the registration service spreads them over workers).
The returned ``T`` maps the (pre-processed) source view onto the (pre-processed) target view.

Two paths:

* ``mode="paper"``: the paper's procedure. 5 attempts, keeping the best fitness. Each attempt registers
  the color-reduced clouds, the top 3 region pairs (``regions`` on) and the clouds cropped to their
  expected overlap (``crop`` on), each with a global stage (3 runs at 8 mm with overlaps 0.9/0.85/0.8,
  best kept) and a local stage (voxels 8/4.5/1 mm with overlap multipliers 3/2/1: color ICP, then
  non-overlap removal and GICP; more than 2 color-ICP failures discard the candidate; then a final color
  ICP and point-to-plane at 1 mm).
* ``mode="fast"`` (default, beyond the paper): pre-rotation already puts the views within the turn
  error (±5-15°) of each other, so local registration from that prior is tried first, from a few yaw
  hypotheses about the turn axis, and verified. When verification fails, the global stages run in order:
  first the **4-DoF turn search** (``turn4dof``: a full yaw sweep about the table normal scored on
  geometry and colour, then ICP over yaw + shift only; an object on a table turns and slides, it does not
  tumble), then, only if that is inconsistent too (a toppled or re-seated object), the **6-DoF** global
  stage (4PCS / FPFH-RANSAC), which must beat the 4-DoF result by ``global_margin`` to replace it. The
  result says which path won (``path``: ``prior`` / ``turn4dof`` / ``global``); ``detail.tried`` lists
  every candidate with its figures.

Candidates are scored by fitness (open3d's definition: inlier source points / source points, inlier
distance ``fitness_distance``) on the full reduced clouds, or on the cropped clouds when ``crop``
(favour overlap) is on. A color-aware fitness (inliers whose quantised color also matches) breaks the
tie that geometry leaves on symmetric objects (cans); both are reported.
"""

from __future__ import annotations

import hashlib
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from common.geometry import rotation_about_line, yaw_deg_about
from services.registration.blocks import ColorICPConfig, colored_icp, overlap_only
from services.registration.dynamic.global_registration import GlobalRegistrationConfig, global_register
from services.registration.dynamic.preprocess import Cloud
from services.registration.dynamic.revolution import RevolutionConfig, fit_revolution, is_revolution
from services.registration.dynamic.turn4dof import TurnSearchConfig, chroma, project_to_turn, search_turn
from services.registration.dynamic.views import DynamicRegistrationError
from services.registration.dynamic.yaw_refine import YawRefineConfig, geometry_pins_yaw, refine_yaw

reg = o3d.pipelines.registration


@dataclass(frozen=True)
class PairConfig:
    """Pair registration settings; paper values where the paper gives them."""

    mode: str = "fast"  # "fast" | "paper"
    regions: bool = False
    crop: bool = False
    attempts: int = 5
    global_method: str = "auto"  # "auto" (= 4pcs) | "4pcs" | "fpfh_ransac" | "fgr"
    global_voxel: float = 0.008
    overlaps: tuple[float, ...] = (0.9, 0.85, 0.8)
    local_voxels: tuple[float, ...] = (0.008, 0.0045, 0.001)
    multipliers: tuple[float, ...] = (3.0, 2.0, 1.0)
    final_voxel: float = 0.001
    max_color_icp_failures: int = 2
    icp_iterations: int = 30
    # fast path
    fast_voxels: tuple[float, ...] = (0.006, 0.003, 0.002)
    fast_max_corr_factor: tuple[float, ...] = (2.5, 2.0, 1.5)
    fast_iterations: tuple[int, ...] = (30, 20, 15)
    yaw_hypotheses_deg: tuple[float, ...] = (0.0, -10.0, 10.0, -20.0, 20.0)  # robot turns err by up to ~18°
    accept_fitness: float = 0.55  # verification of the prior path (fitness on the evaluation clouds)
    accept_rmse: float = 0.0018
    # colour ICP runaway guard (``fast_local``): a level that loses this much fitness is redone with
    # point-to-plane (not the coarse starts: on a can, point-to-plane from the prior slid 24 deg in yaw to a
    # 0.99 fitness, beating the colour starts' 0.8 while they were the ones on the right path)
    runaway_fitness: float = 0.1
    fast_point_to_plane: bool = True  # last point-to-plane pass: sim milk loop error 2.0° -> 0.3°, Chamfer -21 %
    # then a 1-D yaw search about the turn axis scored by fitness + colour agreement (``yaw_refine``): colour
    # ICP leaves a can's yaw 2-5° off, one-sided (realistic alphabet soup: loop 25.9° -> see BENCHMARKS.md)
    yaw_refine: YawRefineConfig = field(default_factory=YawRefineConfig)
    # global stages when the prior path fails verification: first the 4-DoF turn search (yaw about the table
    # normal + shift: an object on a table only turns and slides), the 6-DoF search only if that fails too
    turn_stage: bool = True
    turn_search: TurnSearchConfig = field(default_factory=TurnSearchConfig)
    max_settle_tilt_deg: float = 5.0  # a 6-DoF polish of the 4-DoF result may tilt it this much (re-seating)
    # a prior-path result that tilts the object more than this is a tumble (a face matched onto another),
    # not a turn: it fails the check like a low fitness would
    max_turn_tilt_deg: float = 10.0
    # ... and one that turns more than this away from its prior is a face matched onto its neighbour face (a
    # box's 90-degree look-alikes): priors are within a turn error (robot: up to ~15 deg a pair; imported: the
    # 4-DoF estimate), so it too fails the check and the 4-DoF search decides (castard even frames: a
    # prior-path edge landed 87.5 deg off with fitness 0.86 and opened the loop to 89 deg)
    max_prior_yaw_deg: float = 45.0
    # True: every result is made a turn (yaw about the table normal + shift: the tilt dropped). For a fixed
    # camera (an imported sequence) the table is the same plane in every view and an object standing on it
    # can only turn and slide, so a tilt between views is registration error; on the real castard sequence
    # the 6-DoF edges' tilts (up to 1.8 deg each) added up to a 3.9 deg open loop. None: decided by the
    # session (``reconstruct``: True for a fixed-camera session, False for an arm's).
    turn_only: bool | None = None
    global_margin: float = 0.05  # a 6-DoF result must beat a 4-DoF one by this much score to replace it
    # a body of revolution whose colours do not tell its turn either: the yaw is the prior's (revolution.py)
    revolution: RevolutionConfig = field(default_factory=RevolutionConfig)
    # scoring
    eval_voxel: float = 0.002
    fitness_distance: float = 0.003
    crop_angle_deg: float = 4.0  # unit-sphere overlap: a direction counts as shared within this angle
    seed: int = 0


@dataclass
class PairJob:
    """Everything one pair registration needs; picklable (numpy + frozen dataclasses)."""

    index: int
    source_view: int
    target_view: int
    source: Cloud
    target: Cloud
    center: np.ndarray
    axis: np.ndarray
    config: PairConfig = field(default_factory=PairConfig)
    source_regions: list[Cloud] = field(default_factory=list)
    target_regions: list[Cloud] = field(default_factory=list)
    region_pairs: list[tuple[int, int]] = field(default_factory=list)
    prior: np.ndarray = field(default_factory=lambda: np.eye(4))


def job_fingerprint(job: PairJob) -> str:
    """A digest of everything ``register_pair`` reads: equal digests, equal jobs.

    Lets a result computed earlier (the incremental model, during the acquisition) stand in for the
    same job at the end, and only then: a re-scanned view or another configuration changes the digest.
    """
    h = hashlib.sha256()
    h.update(repr((job.index, job.source_view, job.target_view, job.config, job.region_pairs)).encode())
    for c in (job.source, job.target, *job.source_regions, b"|", *job.target_regions):
        if isinstance(c, bytes):
            h.update(c)
            continue
        for a in (c.xyz, c.rgb, c.normals):
            a = np.ascontiguousarray(a)
            h.update(str((a.dtype.str, a.shape)).encode())
            h.update(a.tobytes())
    for a in (job.center, job.axis, job.prior):
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()


@dataclass
class PairResult:
    """Outcome of one pair: ``T`` maps source onto target; fitness/rmse on the scoring clouds."""

    index: int
    source_view: int
    target_view: int
    T: np.ndarray
    fitness: float
    rmse: float
    color_fitness: float
    path: str  # "prior" | "turn4dof" | "global" | "paper" | "failed"
    candidate: str  # "full" | "crop" | "region0".. : which clouds gave the winning transform
    seconds: float
    attempts: int = 0
    color_icp_failures: int = 0
    detail: dict = field(default_factory=dict)
    # the turn was not observable (a body of revolution, colours the same all round): the yaw is the prior's
    yaw_from_prior: bool = False

    def to_json(self) -> dict:
        return {"index": self.index, "source_view": self.source_view, "target_view": self.target_view,
                "T": np.asarray(self.T).tolist(), "fitness": self.fitness, "rmse_mm": 1000.0 * self.rmse,
                "color_fitness": self.color_fitness, "path": self.path, "candidate": self.candidate,
                "seconds": self.seconds, "attempts": self.attempts,
                "color_icp_failures": self.color_icp_failures, "yaw_from_prior": self.yaw_from_prior,
                "detail": self.detail}


# ----------------------------------------------------------------------------------------- scoring

@dataclass
class _Scorer:
    """Fitness of a transform on fixed evaluation clouds (KD-tree on the target built once)."""

    source: Cloud
    target: Cloud
    distance: float
    tree: cKDTree = field(init=False)

    def __post_init__(self) -> None:
        self.tree = cKDTree(self.target.xyz.astype(np.float64))

    def __call__(self, T: np.ndarray) -> tuple[float, float, float]:
        """(fitness, inlier rmse, color fitness) of ``T`` applied to the source."""
        if len(self.source) == 0 or len(self.target) == 0:
            return 0.0, np.inf, 0.0
        pts = self.source.xyz.astype(np.float64) @ T[:3, :3].T + T[:3, 3]
        d, j = self.tree.query(pts, k=1, distance_upper_bound=self.distance)
        inl = np.isfinite(d)
        n_in = int(inl.sum())
        if n_in == 0:
            return 0.0, np.inf, 0.0
        same = np.all(self.source.rgb[inl] == self.target.rgb[j[inl]], axis=1)
        return n_in / len(pts), float(np.sqrt(np.mean(d[inl] ** 2))), float(same.sum()) / len(pts)

    def refit_shift(self, T: np.ndarray, iterations: int = 2, max_points: int = 1000) -> np.ndarray:
        """``T`` with its translation re-fitted by point-to-plane least squares (rotation kept): a yaw tried
        about an estimated centre a little off the object's own axis then costs no geometric fit."""
        src = self.source.xyz.astype(np.float64)
        if len(src) > max_points:
            src = src[np.linspace(0, len(src) - 1, max_points).astype(int)]
        tn = self.target.normals.astype(np.float64)
        T = np.array(T, dtype=float)
        for _ in range(iterations):
            p = src @ T[:3, :3].T + T[:3, 3]
            d, j = self.tree.query(p, k=1, distance_upper_bound=2.0 * self.distance)
            ok = np.isfinite(d)
            if ok.sum() < 20:
                break
            n = tn[j[ok]]
            r = np.einsum("ij,ij->i", p[ok] - self.target.xyz[j[ok]].astype(np.float64), n)
            A = n.T @ n + 1e-6 * np.eye(3)  # a can's shift along its axis is free: keep it small
            T[:3, 3] += np.linalg.solve(A, -n.T @ r)
        return T

    def colour_distance(self, T: np.ndarray) -> tuple[float, float, float]:
        """(fitness, mean chromaticity difference, point-to-plane rmse in mm) of the inlier pairs of ``T``.

        The chromaticity difference (``turn4dof.chroma``, shading-tolerant) is a smooth colour-agreement
        measure where the exact-colour count above moves in steps. The point-to-plane rmse is flat along a
        surface's own symmetry (a can's yaw) and rises off it (a box's), unlike the fitness, which on a
        partial view grows with the overlap and so pulls a can's yaw to one side."""
        if len(self.source) == 0 or len(self.target) == 0:
            return 0.0, np.inf, np.inf
        if not hasattr(self, "_chroma"):
            self._chroma = (chroma(self.source.rgb)[:, :3], chroma(self.target.rgb)[:, :3])
        pts = self.source.xyz.astype(np.float64) @ T[:3, :3].T + T[:3, 3]
        d, j = self.tree.query(pts, k=1, distance_upper_bound=self.distance)
        inl = np.isfinite(d)
        if not inl.any():
            return 0.0, np.inf, np.inf
        cs, ct = self._chroma
        jj = j[inl]
        plane = np.einsum("ij,ij->i", pts[inl] - self.target.xyz[jj], self.target.normals[jj])
        return (float(inl.sum()) / len(pts), float(np.abs(cs[inl] - ct[jj]).sum(axis=1).mean()),
                1000.0 * float(np.sqrt(np.mean(plane ** 2))))


def _score_key(f: float, cf: float) -> float:
    """One number to rank candidates: geometric fitness, with color agreement as a tie-breaker."""
    return f + 0.5 * cf


# ----------------------------------------------------------------------------------------- helpers

def crop_to_overlap(source: Cloud, target: Cloud, center: np.ndarray, T: np.ndarray,
                    angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices of source and target points in their expected overlap (paper: unit-sphere projection).

    Both clouds are centred on ``center`` and projected onto the unit sphere (the source after ``T``);
    a point is kept if the other cloud has a direction within ``angle_deg`` of its own.
    """
    c = np.asarray(center, dtype=np.float64)
    ps = source.xyz.astype(np.float64) @ T[:3, :3].T + T[:3, 3] - c
    pt = target.xyz.astype(np.float64) - c
    us = ps / np.maximum(np.linalg.norm(ps, axis=1, keepdims=True), 1e-9)
    ut = pt / np.maximum(np.linalg.norm(pt, axis=1, keepdims=True), 1e-9)
    chord = 2.0 * np.sin(np.radians(angle_deg) / 2.0)
    ds, _ = cKDTree(ut).query(us, k=1, distance_upper_bound=chord)
    dt, _ = cKDTree(us).query(ut, k=1, distance_upper_bound=chord)
    return np.flatnonzero(np.isfinite(ds)), np.flatnonzero(np.isfinite(dt))


_LOCAL = threading.local()


def _down_cache() -> dict[tuple[int, float], tuple[Cloud, o3d.geometry.PointCloud]]:
    """This thread's cache: a worker's executor may run two pair jobs at once (two coordinators)."""
    cache = getattr(_LOCAL, "down", None)
    if cache is None:
        cache = _LOCAL.down = {}
    return cache


def _down(cloud: Cloud, voxel: float) -> o3d.geometry.PointCloud:
    """Voxel-downsampled open3d copy, memoised for the duration of one pair job (see ``register_pair``).

    A job downsamples the same two clouds at the same voxels several times (hypotheses, levels,
    global fallback); open3d's ICPs do not modify their inputs, so sharing is safe. The cache keeps a
    reference to the cloud so its ``id`` cannot be reused while the entry lives.
    """
    key = (id(cloud), float(voxel))
    cache = _down_cache()
    hit = cache.get(key)
    if hit is not None and hit[0] is cloud:
        return hit[1]
    pcd = cloud.to_o3d()
    if voxel > 0:
        pcd = pcd.voxel_down_sample(voxel)
    pcd.normalize_normals()
    cache[key] = (cloud, pcd)
    return pcd


def _colored_icp(s: o3d.geometry.PointCloud, t: o3d.geometry.PointCloud, max_corr: float, T: np.ndarray,
                 iters: int) -> tuple[np.ndarray, bool]:
    """Color ICP; returns (T, ok). A failure (no correspondences, exception) keeps the input ``T``."""
    out = colored_icp(s, t, max_corr, T, ColorICPConfig(max_iteration=iters))
    return (out.T, True) if out.ok else (T, False)


def _point_to_plane(s: o3d.geometry.PointCloud, t: o3d.geometry.PointCloud, max_corr: float, T: np.ndarray,
                    iters: int) -> np.ndarray:
    r = reg.registration_icp(s, t, max_corr, T, reg.TransformationEstimationPointToPlane(),
                             reg.ICPConvergenceCriteria(relative_fitness=1e-6, relative_rmse=1e-6,
                                                        max_iteration=iters))
    return np.asarray(r.transformation) if r.fitness > 0 else T


def _gicp(s: o3d.geometry.PointCloud, t: o3d.geometry.PointCloud, max_corr: float, T: np.ndarray,
          iters: int) -> np.ndarray:
    if len(s.points) < 10 or len(t.points) < 10:
        return T
    try:
        r = reg.registration_generalized_icp(
            s, t, max_corr, T, reg.TransformationEstimationForGeneralizedICP(),
            reg.ICPConvergenceCriteria(relative_fitness=1e-6, relative_rmse=1e-6, max_iteration=iters))
    except RuntimeError:
        return T
    return np.asarray(r.transformation) if r.fitness > 0 and np.isfinite(r.transformation).all() else T


#: The dynamic stage's global search stops after its base count only, never on a clock: a time budget makes
#: the result depend on the machine's load (fewer bases tried on a busy machine, another pose found), and the
#: same session must give the same model on every run. 4PCS's base count (``default_max_bases``) bounds it.
DETERMINISTIC_GLOBAL = GlobalRegistrationConfig(fourpcs_max_time_s=float("inf"))


def global_align(source: Cloud, target: Cloud, voxel: float, overlap: float, seed: int,
                 method: str = "auto") -> tuple[np.ndarray, float, str]:
    """Global registration behind one call: (T, score, method used); ``auto`` is 4PCS (seeded, no time limit)."""
    m = "4pcs" if method == "auto" else method
    res = global_register(source.xyz, target.xyz, method=m, voxel=voxel, overlap=overlap, seed=seed,
                          config=DETERMINISTIC_GLOBAL)
    return np.asarray(res.T, dtype=float), float(res.lcp_score), m


# ----------------------------------------------------------------------------------------- local stages

def paper_local(source: Cloud, target: Cloud, T0: np.ndarray, cfg: PairConfig) -> tuple[np.ndarray | None, int]:
    """The paper's local stage from a global estimate; (T or None if discarded, color-ICP failures)."""
    T = T0
    fails = 0
    for voxel, mult in zip(cfg.local_voxels, cfg.multipliers, strict=True):
        s, t = _down(source, voxel), _down(target, voxel)
        T, ok = _colored_icp(s, t, 1.5 * voxel, T, cfg.icp_iterations)
        fails += 0 if ok else 1
        if fails > cfg.max_color_icp_failures:
            return None, fails
        so, to = overlap_only(s, t, T, mult)
        T = _gicp(so, to, 1.5 * voxel, T, cfg.icp_iterations)
    s, t = _down(source, cfg.final_voxel), _down(target, cfg.final_voxel)
    T, ok = _colored_icp(s, t, 1.5 * cfg.final_voxel, T, cfg.icp_iterations)
    fails += 0 if ok else 1
    if fails > cfg.max_color_icp_failures:
        return None, fails
    T = _point_to_plane(s, t, 1.5 * cfg.final_voxel, T, cfg.icp_iterations)
    return T, fails


def fast_local(source: Cloud, target: Cloud, T0: np.ndarray, cfg: PairConfig,
               start_level: int = 0, scorer: _Scorer | None = None) -> tuple[np.ndarray, int]:
    """Coarse-to-fine color ICP (optionally then point-to-plane) from ``T0``; (T, color-ICP failures).

    With a ``scorer``, a level whose colour ICP runs away (loses ``runaway_fitness`` of geometric fitness) is
    redone with point-to-plane from the same start, and the fitter of that and the start is kept. Why: colour
    ICP can run away when two views' colours disagree (shading, exposure, colour-to-depth misregistration):
    on a realistic milk acquisition's edge 11 -> 10 it took a 0.82-fitness start to a 38 deg tilt at the 3 mm
    level, while point-to-plane from the same start stayed at 0.82 (0.6 mm off the true edge). Only a large
    loss counts: on a can a right colour step may cost a little fitness (the overlap a wrong yaw gains)."""
    T = T0
    fails = 0
    fit = None if scorer is None else scorer(T)[0]
    levels = list(zip(cfg.fast_voxels, cfg.fast_max_corr_factor, cfg.fast_iterations, strict=True))
    for voxel, k, iters in levels[start_level:]:
        s, t = _down(source, voxel), _down(target, voxel)
        Tc, ok = _colored_icp(s, t, k * voxel, T, iters)
        fails += 0 if ok else 1
        if fit is not None:
            fc = scorer(Tc)[0]
            if fc < fit - cfg.runaway_fitness:
                Tp = _point_to_plane(s, t, k * voxel, T, iters)
                fc, Tc = max([(scorer(Tp)[0], Tp), (fit, T)], key=lambda x: x[0])
            fit = fc
        T = Tc
    if cfg.fast_point_to_plane:
        T = _point_to_plane(s, t, cfg.fast_voxels[-1], T, cfg.icp_iterations)
    return T, fails


# ----------------------------------------------------------------------------------------- the pair

@dataclass
class _Candidate:
    name: str
    source: Cloud
    target: Cloud


def _candidates(job: PairJob, cfg: PairConfig) -> list[_Candidate]:
    out = [_Candidate("full", job.source, job.target)]
    if cfg.crop:
        i_s, i_t = crop_to_overlap(job.source, job.target, job.center, job.prior, cfg.crop_angle_deg)
        if len(i_s) > 50 and len(i_t) > 50:
            out.append(_Candidate("crop", job.source.subset(i_s), job.target.subset(i_t)))
    if cfg.regions:
        for k, (a, b) in enumerate(job.region_pairs):
            if a < len(job.source_regions) and b < len(job.target_regions):
                out.append(_Candidate(f"region{k}", job.source_regions[a], job.target_regions[b]))
    return out


def _evaluation_clouds(job: PairJob, cfg: PairConfig) -> _Scorer:
    src = job.source.downsampled(cfg.eval_voxel)
    tgt = job.target.downsampled(cfg.eval_voxel)
    if cfg.crop:  # favour overlap: score on the expected overlap only
        i_s, i_t = crop_to_overlap(src, tgt, job.center, job.prior, cfg.crop_angle_deg)
        if len(i_s) > 50 and len(i_t) > 50:
            src, tgt = src.subset(i_s), tgt.subset(i_t)
    return _Scorer(src, tgt, cfg.fitness_distance)


def register_pair(job: PairJob) -> PairResult:
    """Register ``job.source`` onto ``job.target``; see the module doc for the two paths."""
    t0 = time.perf_counter()
    cfg = job.config
    if len(job.source) < 50 or len(job.target) < 50:
        raise DynamicRegistrationError("pair clouds too small to register", code="empty_view",
                                       detail={"pair": job.index, "source": len(job.source),
                                               "target": len(job.target)})
    if cfg.mode not in ("fast", "paper"):
        raise DynamicRegistrationError(f"unknown pair mode {cfg.mode!r}", code="bad_value",
                                       detail={"modes": ["fast", "paper"]})
    _down_cache().clear()
    try:
        scorer = _evaluation_clouds(job, cfg)
        res = _register_paper(job, cfg, scorer) if cfg.mode == "paper" else _register_fast(job, cfg, scorer)
    finally:
        _down_cache().clear()
    res.seconds = time.perf_counter() - t0
    return res


def _yaw(job: PairJob, deg: float) -> np.ndarray:
    return rotation_about_line(job.axis, job.center, np.radians(deg))


def _register_fast(job: PairJob, cfg: PairConfig, scorer: _Scorer) -> PairResult:
    best: tuple[float, np.ndarray, str, tuple[float, float, float]] | None = None
    fails_total = 0
    tried: list[dict] = []
    for cand in _candidates(job, cfg):
        # coarse color ICP from each yaw hypothesis, keep the best, then refine it
        voxel, k = cfg.fast_voxels[0], cfg.fast_max_corr_factor[0]
        s, t = _down(cand.source, voxel), _down(cand.target, voxel)
        coarse = []
        for h in cfg.yaw_hypotheses_deg:
            T, ok = _colored_icp(s, t, k * voxel, _yaw(job, h) @ job.prior, cfg.icp_iterations)
            f, _, cf = scorer(T)
            coarse.append((_score_key(f, cf), T))
        T0 = max(coarse, key=lambda x: x[0])[1]
        T, fails = fast_local(cand.source, cand.target, T0, cfg, start_level=1, scorer=scorer)
        fails_total += fails
        sc = scorer(T)
        tried.append({"candidate": cand.name, "fitness": sc[0], "color_fitness": sc[2]})
        key = _score_key(sc[0], sc[2])
        if best is None or key > best[0]:
            best = (key, T, cand.name, sc)
    assert best is not None
    best = _yaw_refined(job, cfg, scorer, best, tried)
    _, T, name, (f, rmse, cf) = best
    path = "prior"
    prior_tilt, prior_yaw = tilt_deg(T, job.axis), yaw_from_prior_deg(T, job.prior, job.axis)
    tried[-1]["tilt_deg"] = round(prior_tilt, 2)
    tried[-1]["yaw_from_prior_deg"] = round(prior_yaw, 2)
    off_turn = not is_turn_near_prior(T, job.prior, job.axis, cfg)
    if cfg.turn_stage and (not _verified(f, rmse, cfg) or off_turn):
        if off_turn:
            best = (-np.inf, T, name, (f, rmse, cf))  # a tumble: any turn found beats it
        key, T4, sc4 = _turn_stage(job, cfg, scorer, tried)
        if key > best[0]:
            best, path = _yaw_refined(job, cfg, scorer, (key, T4, "full", sc4), tried), "turn4dof"
        _, T, name, (f, rmse, cf) = best
    if not _verified(f, rmse, cfg):
        # still inconsistent (a toppled or re-seated object): global 6-DoF stage, then the same local refinement
        margin = cfg.global_margin if path == "turn4dof" else 0.0
        rng = np.random.default_rng(cfg.seed + 7919 * job.index)
        for overlap in cfg.overlaps:
            Tg, _, method = global_align(job.source, job.target, cfg.global_voxel, overlap,
                                         int(rng.integers(1 << 30)), cfg.global_method)
            Tl, fails = fast_local(job.source, job.target, Tg, cfg, scorer=scorer)
            fails_total += fails
            sc = scorer(Tl)
            tried.append({"candidate": f"global_{method}_{overlap}", "fitness": sc[0], "color_fitness": sc[2]})
            if _score_key(sc[0], sc[2]) > best[0] + margin:
                best = (_score_key(sc[0], sc[2]), Tl, "full", sc)
                path, margin = "global", 0.0
        _, T, name, (f, rmse, cf) = best
    detail: dict = {"tried": tried}
    from_prior = _yaw_from_prior(job, cfg, scorer, T)
    if from_prior is not None:
        T, detail["yaw_from_prior"] = from_prior
        f, rmse, cf = scorer(T)
    if cfg.turn_only and path != "global":  # a global result means the object was re-seated: keep its tilt
        # the 4-DoF transform nearest the 6-DoF fit (its yaw, the centre where it moves it). A 4-DoF ICP
        # (``refine_turn``) instead left the castard loop at 3.0 deg (its point-to-point rows pull the yaw on
        # partial overlaps; 1.0 deg without them); the projection closes it to 0.6 deg
        detail["turn_only"] = {"tilt_dropped_deg": round(tilt_deg(T, job.axis), 3)}
        T = project_to_turn(T, job.axis, job.center)
        f, rmse, cf = scorer(T)
    return PairResult(job.index, job.source_view, job.target_view, T, f, rmse, cf, path, name, 0.0,
                      attempts=1, color_icp_failures=fails_total, detail=detail,
                      yaw_from_prior=from_prior is not None)


def _yaw_from_prior(job: PairJob, cfg: PairConfig, scorer: _Scorer, T: np.ndarray) -> tuple[np.ndarray, dict] | None:
    """``T`` turned about the object's fitted axis to the prior's yaw, when neither the shape nor the colours
    can tell the turn (both views bodies of revolution, the colour difference flat +-``probe_deg`` about that
    axis); None otherwise. Its tilt and shift are the registration's (the shift re-fitted after the turn)."""
    rc = cfg.revolution
    if not rc.enabled:
        return None
    fits = [fit_revolution(c.xyz, c.normals, job.axis, job.center, rc) for c in (job.target, job.source)]
    if not all(is_revolution(fit, rc) for fit in fits):
        return None
    point = fits[0].point  # the target's axis: the source, posed by ``T``, lies on the target's surface
    base = scorer.colour_distance(T)[1]
    rises = [scorer.colour_distance(scorer.refit_shift(rotation_about_line(job.axis, point, np.radians(d)) @ T))[1]
             - base for d in (-rc.probe_deg, rc.probe_deg)]
    if min(rises) > rc.max_colour_rise:  # the colours change both ways: they tell the turn
        return None
    off = yaw_deg_about(job.axis, np.asarray(T)[:3, :3] @ np.asarray(job.prior)[:3, :3].T)
    T2 = scorer.refit_shift(rotation_about_line(job.axis, point, np.radians(-off)) @ T)
    if rc.polish:  # tilt and shift once more where the views now overlap, the yaw put back to the prior's
        s, t = _down(job.source, cfg.fast_voxels[-1]), _down(job.target, cfg.fast_voxels[-1])
        T3 = _point_to_plane(s, t, cfg.fast_voxels[-1], T2, cfg.icp_iterations)
        back = yaw_deg_about(job.axis, T3[:3, :3] @ np.asarray(job.prior)[:3, :3].T)
        T2 = scorer.refit_shift(rotation_about_line(job.axis, point, np.radians(-back)) @ T3)
    return T2, {"registered_yaw_from_prior_deg": round(off, 2), "colour_rise": [round(r, 4) for r in rises],
                "on_surface": [round(fit.on_surface, 4) for fit in fits]}


def _yaw_refined(job: PairJob, cfg: PairConfig, scorer: _Scorer,
                 best: tuple[float, np.ndarray, str, tuple[float, float, float]], tried: list[dict]
                 ) -> tuple[float, np.ndarray, str, tuple[float, float, float]]:
    """``best`` after the 1-D yaw search about the turn axis (``yaw_refine``), scored like every candidate."""
    key, T, name, sc = best
    if not cfg.yaw_refine.enabled:
        return best
    pinned, rise = geometry_pins_yaw(T, lambda Ty: scorer.colour_distance(Ty)[2], job.axis, job.center,
                                     cfg.yaw_refine, refit=scorer.refit_shift)
    if pinned:  # the shape fixes the yaw (a box): the ICP's yaw stands
        tried.append({"candidate": f"{name}+yaw", "pinned_by_geometry": True, "plane_rise_mm": round(rise, 3)})
        return best
    f0 = sc[0]

    def colour(Ty: np.ndarray) -> float:  # geometric fit and colour agreement (see YawRefineConfig)
        f, dc, plane_mm = scorer.colour_distance(Ty)
        return -dc - cfg.yaw_refine.plane_rmse_weight * plane_mm if f >= f0 - cfg.yaw_refine.fitness_drop else -np.inf

    r = refine_yaw(T, colour, job.axis, job.center, cfg.yaw_refine, refit=scorer.refit_shift)
    tried.append({"candidate": f"{name}+yaw", "yaw_offset_deg": r.offset_deg, "score_before": r.score_before,
                  "score_after": r.score_after})
    if r.offset_deg == 0.0:
        return best
    sc = scorer(r.T)
    return _score_key(sc[0], sc[2]), r.T, name, sc


def yaw_from_prior_deg(T: np.ndarray, prior: np.ndarray, axis: np.ndarray) -> float:
    """How far ``T`` turns about ``axis`` away from ``prior`` (degrees, unsigned)."""
    return abs(yaw_deg_about(axis, np.asarray(T)[:3, :3] @ np.asarray(prior)[:3, :3].T))


def is_turn_near_prior(T: np.ndarray, prior: np.ndarray, axis: np.ndarray, cfg: PairConfig) -> bool:
    """A prior-path result is a plausible turn: it tips the table normal by at most ``max_turn_tilt_deg``
    and turns at most ``max_prior_yaw_deg`` away from its prior."""
    return (tilt_deg(T, axis) <= cfg.max_turn_tilt_deg
            and yaw_from_prior_deg(T, prior, axis) <= cfg.max_prior_yaw_deg)


def tilt_deg(T: np.ndarray, axis: np.ndarray) -> float:
    """How far ``T`` tips the turn axis (degrees): 0 for a pure turn about the table normal.

    As the angle between the axis and its image via atan2(|a x Ra|, a . Ra): arccos of a dot product near 1
    loses half the digits (one ulp of the dot product reads as 1.2e-6 deg), atan2 keeps them."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    b = np.asarray(T, dtype=float)[:3, :3] @ a
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b)), float(a @ b))))


def _verified(f: float, rmse: float, cfg: PairConfig) -> bool:
    """The consistency check of a pair result: enough overlap, small residual."""
    return f >= cfg.accept_fitness and rmse <= cfg.accept_rmse


def _turn_stage(job: PairJob, cfg: PairConfig, scorer: _Scorer, tried: list[dict]
                ) -> tuple[float, np.ndarray, tuple[float, float, float]]:
    """4-DoF turn search from the prior, then a 6-DoF local polish kept only if it tilts the result no more
    than ``max_settle_tilt_deg`` (an object settling differently); (score key, T, scores) of the better."""
    tr = search_turn(job.source, job.target, job.axis, job.center, prior=job.prior, config=cfg.turn_search)
    out = [(tr.T, "turn4dof")]
    Tl, _ = fast_local(job.source, job.target, tr.T, cfg, start_level=1, scorer=scorer)
    tilt = tilt_deg(Tl @ np.linalg.inv(tr.T), job.axis)
    if tilt <= cfg.max_settle_tilt_deg:
        out.append((Tl, "turn4dof+icp"))
    best = None
    for T, name in out:
        sc = scorer(T)
        key = _score_key(sc[0], sc[2])
        tried.append({"candidate": name, "yaw_deg": round(tr.yaw_deg, 2), "fitness": sc[0], "color_fitness": sc[2],
                      "tilt_deg": round(tilt, 2) if name != "turn4dof" else 0.0})
        if best is None or key > best[0]:
            best = (key, T, sc)
    assert best is not None
    return best


def _register_paper(job: PairJob, cfg: PairConfig, scorer: _Scorer) -> PairResult:
    rng = np.random.default_rng(cfg.seed + 7919 * job.index)
    best: tuple[float, np.ndarray, str, tuple[float, float, float]] | None = None
    fails_total = 0
    tried: list[dict] = []
    for attempt in range(cfg.attempts):
        for cand in _candidates(job, cfg):
            glob = []
            for overlap in cfg.overlaps:
                Tg, _, method = global_align(cand.source, cand.target, cfg.global_voxel, overlap,
                                             int(rng.integers(1 << 30)), cfg.global_method)
                glob.append((scorer(Tg)[0], Tg))
            Tg = max(glob, key=lambda x: x[0])[1]
            T, fails = paper_local(cand.source, cand.target, Tg, cfg)
            fails_total += fails
            if T is None:
                tried.append({"attempt": attempt, "candidate": cand.name, "discarded": True})
                continue
            sc = scorer(T)
            tried.append({"attempt": attempt, "candidate": cand.name, "fitness": sc[0]})
            if best is None or sc[0] > best[0]:
                best = (sc[0], T, cand.name, sc)
    if best is None:
        return PairResult(job.index, job.source_view, job.target_view, np.asarray(job.prior), 0.0, np.inf,
                          0.0, "failed", "none", 0.0, attempts=cfg.attempts, color_icp_failures=fails_total,
                          detail={"tried": tried})
    _, T, name, (f, rmse, cf) = best
    return PairResult(job.index, job.source_view, job.target_view, T, f, rmse, cf, "paper", name, 0.0,
                      attempts=cfg.attempts, color_icp_failures=fails_total, detail={"tried": tried})
