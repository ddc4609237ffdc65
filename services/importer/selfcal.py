"""Self-calibration of the focal length from a sequence that completes a turn.

Why: a focal length a few percent off (a README's intrinsics from another resolution or unit, a nominal
value) stretches every view sideways against its depth, the same way in the camera frame whatever the
object's angle. Each pair then registers with a small yaw bias that does not cancel around the loop: on
the real castard D415 sequence the pairs' yaws summed to 8.2 deg short of a full turn with the README's
fx = 597.5, and to 0.1 deg with fx x 1.045 (diagnosed with this very search). The loop of a sequence that
turns the object once around is the one ground truth a fixed-camera sequence carries, so the focal
length that closes it is measurable.

What is searched: one scalar ``s`` multiplying fx and fy (cx, cy kept). Scaling the focal by ``s`` maps a
camera-frame point (x, y, z) to (x/s, y/s, z), so the isolated views are rescaled directly, with no
re-isolation. The depth scale needs no search: scaling the depth by ``k`` is the same shape as scaling
the focal by ``k`` (and the whole object by ``k``), i.e. this one ``s`` covers both.

For a given ``s``, every neighbour pair (and the closing pair last -> first) is refined by point-to-plane
ICP from the 4-DoF turn search's result and projected to a turn (yaw about the table normal + shift: a
fixed camera sees one table, and an object standing on it can only turn and slide); the signed yaw of
their composition is the loop error ``e(s)``. ``e`` is close to linear in ``s``: a secant search finds its
zero inside ``scale_range``. The result is applied only when the sequence completes a turn (the turns
found sum to at least ``min_turn_deg`` and the closing pair overlaps), the loop is open by less than
``max_loop_deg`` (more is a wrong pair, not a focal error) and closes better by at least ``min_gain_deg``;
otherwise ``s = 1`` and the reason is reported. The pairs' mean overlap (fitness) is reported per scale but
not used: it grows with ``s`` whatever the truth (a laterally shrunk cloud has more close neighbours; on
the twin it rose from x 1 to x 1.03 with the right focal length), so it cannot tell the right scale.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
import open3d as o3d

from common.geometry import invert, make_transform, yaw_deg_about
from common.messages import Intrinsics
from services.registration.api import DynamicView, TurnResult, known_turn, project_to_turn

reg = o3d.pipelines.registration


@dataclass(frozen=True)
class FocalSearchConfig:
    """When and how the focal-length scale is searched (``enabled=False``: the intrinsics are kept)."""

    enabled: bool = True
    scale_range: tuple[float, float] = (0.85, 1.15)  # a focal off by more than 15 % is a wrong file, not a calibration
    first_step: float = 0.03  # the secant search's second point: s = 1 + first_step
    iterations: int = 4  # secant steps after the first two evaluations
    tolerance_deg: float = 0.15  # stop once |loop yaw| is below this
    min_turn_deg: float = 300.0  # the turns found must add up to (nearly) a full turn
    min_closing_fitness: float = 0.3  # and the last view must overlap the first
    max_loop_deg: float = 30.0  # a loop further off than this is a wrong pair (a face matched the wrong way)
    min_gain_deg: float = 1.0  # apply only when the loop closes better by at least this much
    voxel: float = 0.002  # m
    icp_distances: tuple[float, ...] = (0.006, 0.003, 0.0015)  # m, coarse to fine
    prior_agreement_deg: float = 10.0  # a pair search further than this from its solved turn is not a prior

    def __post_init__(self) -> None:
        lo, hi = self.scale_range
        if not 0.5 < lo < 1.0 < hi < 2.0:
            raise ValueError(f"scale_range must bracket 1 within (0.5, 2), got {self.scale_range}")
        if not (0 < self.first_step < hi - 1.0) or self.iterations < 0 or self.tolerance_deg <= 0:
            raise ValueError("first_step must be positive and inside scale_range; iterations >= 0; tolerance > 0")
        if not self.icp_distances or min(self.icp_distances) <= 0 or self.voxel <= 0:
            raise ValueError("icp_distances and voxel must be positive")


@dataclass
class FocalCalibration:
    """What the search found and whether it was applied (``scale`` is 1 when not)."""

    scale: float
    applied: bool
    reason: str
    loop_yaw_before_deg: float | None = None
    loop_yaw_after_deg: float | None = None
    total_turn_deg: float | None = None
    closing_fitness: float | None = None
    evaluations: list[dict] | None = None
    fx_before: float | None = None
    fx_after: float | None = None
    seconds: float = 0.0

    def to_json(self) -> dict:
        out = asdict(self)
        for k in ("scale", "loop_yaw_before_deg", "loop_yaw_after_deg", "total_turn_deg", "closing_fitness",
                  "fx_before", "fx_after", "seconds"):
            if out[k] is not None:
                out[k] = round(float(out[k]), 4)
        return out


def scale_intrinsics(K: Intrinsics, s: float) -> Intrinsics:
    """``K`` with fx and fy multiplied by ``s`` (principal point kept)."""
    return Intrinsics(width=K.width, height=K.height, fx=K.fx * s, fy=K.fy * s, cx=K.cx, cy=K.cy)


def rescale_points(xyz_base: np.ndarray, T_base_camera: np.ndarray, s: float) -> np.ndarray:
    """Points in ``base`` as they would have been back-projected with the focal length times ``s``."""
    T_cb = invert(T_base_camera)
    pc = np.asarray(xyz_base, dtype=np.float64) @ T_cb[:3, :3].T + T_cb[:3, 3]
    pc[:, :2] /= s
    return pc @ T_base_camera[:3, :3].T + T_base_camera[:3, 3]


def solved_prior(target: DynamicView, source: DynamicView, axis: np.ndarray, turn_deg: float) -> np.ndarray:
    """View ``source`` onto ``target`` for an object turned by ``turn_deg`` between them: centres stacked on the
    table, then the turn undone about the axis through the target's centre."""
    shift = np.asarray(target.center, np.float64) - np.asarray(source.center, np.float64)
    shift -= float(shift @ axis) * axis
    return known_turn(axis, np.asarray(target.center, np.float64), -turn_deg, np.zeros(3)) @ make_transform(None, shift)


class LoopProbe:
    """The signed loop yaw of a turn sequence for any focal scale ``s`` (see the module doc)."""

    def __init__(self, views: list[DynamicView], T_base_camera: np.ndarray, searches: list[TurnResult],
                 config: FocalSearchConfig, turns_deg: list[float] | None = None) -> None:
        if len(searches) != len(views) - 1 or len(views) < 3:
            raise ValueError("one turn search per neighbour pair, at least 3 views")
        self.cfg = config
        self.T_bc = np.asarray(T_base_camera, dtype=np.float64)
        self.axis = np.asarray(views[0].table.normal, dtype=np.float64)
        self.xyz = [np.asarray(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(
            np.asarray(v.xyz, np.float64))).voxel_down_sample(config.voxel).points) for v in views]
        self.priors = [np.asarray(r.T, dtype=np.float64) for r in searches]  # view k+1 onto view k
        for k, turn in enumerate(turns_deg or []):  # a search the solved loop overruled starts from the solved turn
            if abs((-searches[k].yaw_deg - turn + 180.0) % 360.0 - 180.0) > config.prior_agreement_deg:
                self.priors[k] = solved_prior(views[k], views[k + 1], self.axis, turn)

    def _cloud(self, k: int, s: float) -> o3d.geometry.PointCloud:
        p = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rescale_points(self.xyz[k], self.T_bc, s)))
        p.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3 * self.cfg.voxel, max_nn=30))
        return p

    def _refine(self, src: o3d.geometry.PointCloud, tgt: o3d.geometry.PointCloud, T: np.ndarray,
                center: np.ndarray) -> tuple[np.ndarray, float]:
        fit = 0.0
        for d in self.cfg.icp_distances:
            r = reg.registration_icp(src, tgt, d, T, reg.TransformationEstimationPointToPlane(),
                                     reg.ICPConvergenceCriteria(max_iteration=40))
            T, fit = np.asarray(r.transformation), float(r.fitness)
        return project_to_turn(T, self.axis, center), fit

    def evaluate(self, s: float) -> dict:
        """``{"scale", "loop_yaw_deg", "mean_fitness", "closing_fitness"}`` at focal scale ``s``."""
        clouds = [self._cloud(k, s) for k in range(len(self.xyz))]
        centers = [np.asarray(c.get_center()) for c in clouds]
        chain, fits = np.eye(4), []
        for k, prior in enumerate(self.priors):  # view k+1 onto view k
            T, f = self._refine(clouds[k + 1], clouds[k], prior, centers[k])
            chain = chain @ T
            fits.append(f)
        T_close, f_close = self._refine(clouds[0], clouds[-1], invert(chain), centers[-1])  # first onto last
        loop = chain @ T_close  # first -> last -> ... -> first: identity when the loop closes
        return {"scale": float(s), "loop_yaw_deg": float(yaw_deg_about(self.axis, loop[:3, :3])),
                "mean_fitness": float(np.mean(fits + [f_close])), "closing_fitness": f_close}


def calibrate_focal(views: list[DynamicView], T_base_camera: np.ndarray, searches: list[TurnResult],
                    total_turn_deg: float, intrinsics: Intrinsics | None,
                    config: FocalSearchConfig | None = None, turns_deg: list[float] | None = None,
                    loop_closes: bool | None = None) -> FocalCalibration:
    """The focal scale that closes the loop of a full-turn sequence, or ``scale=1`` and why not.

    ``total_turn_deg`` and ``loop_closes`` come from the solved loop (``turn_graph``: the last view overlaps
    the first, the turns add up to a full turn), not from the summed pair estimates, which under-count when a
    pair is wrong; ``turns_deg`` (the solved neighbour turns) seed the pairs whose search they overruled."""
    cfg = config or FocalSearchConfig()
    t0 = time.perf_counter()
    fx = intrinsics.fx if intrinsics is not None else None
    if not cfg.enabled:
        return FocalCalibration(1.0, False, "switched off", fx_before=fx, fx_after=fx)
    if loop_closes is False:
        return FocalCalibration(1.0, False, "the solved turns do not close a loop (the last view does not come "
                                "back to the first): no loop to close", total_turn_deg=total_turn_deg,
                                fx_before=fx, fx_after=fx)
    if abs(total_turn_deg) < cfg.min_turn_deg:
        return FocalCalibration(1.0, False, f"the sequence turns {abs(total_turn_deg):.0f} deg, not a full turn "
                                f"(>= {cfg.min_turn_deg:.0f}): no loop to close", total_turn_deg=total_turn_deg,
                                fx_before=fx, fx_after=fx)
    probe = LoopProbe(views, T_base_camera, searches, cfg, turns_deg)
    evals = [probe.evaluate(1.0)]
    base = evals[0]
    if base["closing_fitness"] < cfg.min_closing_fitness:
        return FocalCalibration(1.0, False, f"the last view overlaps the first too little "
                                f"({base['closing_fitness']:.2f} < {cfg.min_closing_fitness})",
                                base["loop_yaw_deg"], base["loop_yaw_deg"], total_turn_deg, base["closing_fitness"],
                                evals, fx, fx, time.perf_counter() - t0)
    if abs(base["loop_yaw_deg"]) > cfg.max_loop_deg:
        return FocalCalibration(1.0, False, f"the loop is {base['loop_yaw_deg']:.1f} deg open: a pair is wrong, "
                                "not the focal length", base["loop_yaw_deg"], base["loop_yaw_deg"], total_turn_deg,
                                base["closing_fitness"], evals, fx, fx, time.perf_counter() - t0)
    lo, hi = cfg.scale_range
    evals.append(probe.evaluate(1.0 + cfg.first_step))
    for _ in range(cfg.iterations):
        a, b = evals[-2], evals[-1]
        if abs(b["loop_yaw_deg"]) <= cfg.tolerance_deg:
            break
        slope = (b["loop_yaw_deg"] - a["loop_yaw_deg"]) / (b["scale"] - a["scale"])
        if abs(slope) < 1e-6:
            break
        nxt = float(np.clip(b["scale"] - b["loop_yaw_deg"] / slope, lo, hi))
        if any(abs(nxt - e["scale"]) < 1e-4 for e in evals):
            break
        evals.append(probe.evaluate(nxt))
    best = min(evals, key=lambda e: abs(e["loop_yaw_deg"]))
    gain = abs(base["loop_yaw_deg"]) - abs(best["loop_yaw_deg"])
    rounded = [{k: round(v, 4) for k, v in e.items()} for e in evals]
    common = dict(loop_yaw_before_deg=base["loop_yaw_deg"], total_turn_deg=total_turn_deg,
                  closing_fitness=base["closing_fitness"], evaluations=rounded, fx_before=fx)
    if gain < cfg.min_gain_deg:
        why = f"the loop closes within {gain:.2f} deg of the best scale already"
        return FocalCalibration(1.0, False, why, loop_yaw_after_deg=base["loop_yaw_deg"], fx_after=fx,
                                seconds=time.perf_counter() - t0, **common)
    s = best["scale"]
    return FocalCalibration(s, True, f"the loop closes {gain:.2f} deg better with fx, fy x {s:.4f}",
                            loop_yaw_after_deg=best["loop_yaw_deg"], fx_after=None if fx is None else fx * s,
                            seconds=time.perf_counter() - t0, **common)
