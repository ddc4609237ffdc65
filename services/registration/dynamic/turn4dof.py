"""Turns as turns: a 4-DoF global search (yaw about the table normal + a shift) between two views.

An object standing on the table after a turn differs from the previous view by a yaw about the table
normal and a shift (mostly in the table plane), plus at most a small tilt when it settles differently. A
6-DoF global search (4PCS, FPFH-RANSAC) ignores that and on real data tumbles views onto wrong faces; a
search over the 4 real degrees of freedom cannot tumble and is cheap:

1. **yaw sweep**: every ``yaw_step_deg`` over ``yaw_range_deg`` about the axis through the centre, each
   hypothesis scored by geometry (share of source points with a target point within ``score_distance``)
   plus colour (the share whose colour also agrees): geometry alone leaves a box's 180-degree symmetry open;
2. **4-DoF ICP** from the best few (well-separated) hypotheses: point-to-plane plus a little
   point-to-point, solved for (yaw, tx, ty, tz) only, coarse to fine;
3. the best refined hypothesis by the same score.

Plain numpy/scipy on picklable ``Cloud``s; ``T`` maps the source onto the target, like a pair result.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from common.geometry import make_transform, rotation_about_axis, yaw_deg_about
from services.registration.cloud import chromaticity
from services.registration.dynamic.preprocess import Cloud


@dataclass(frozen=True)
class TurnSearchConfig:
    """Settings of the 4-DoF search; sizes suit grocery-sized objects seen by a D4xx at 0.3-0.6 m."""

    yaw_step_deg: float = 7.5
    yaw_range_deg: tuple[float, float] = (-180.0, 180.0)
    sweep_voxel: float = 0.005  # m; the sweep scores a cloud this coarse
    sweep_shift_corr: float = 0.025  # m; each yaw first gets its shift by a few ICP steps with this reach
    sweep_shift_iterations: int = 6  # (partial views put the two centre estimates 1-2 cm apart)
    score_distance: float = 0.006  # m; sweep inlier distance
    color_weight: float = 0.5  # score = fitness + color_weight * colour fitness
    # two colours agree when their chromaticities (r, g, b) / (r + g + b) differ by at most this (L1) and
    # their brightnesses by at most a factor brightness_ratio: shading changes as a face turns to the light
    color_tolerance: float = 0.08
    brightness_ratio: float = 2.0
    keep: int = 8  # hypotheses refined by ICP (4 left the flat cream-cheese box 87 deg off at 60 deg, bench turns)
    icp_voxels: tuple[float, ...] = (0.005, 0.003, 0.002)
    icp_corr_factor: tuple[float, ...] = (3.0, 2.0, 1.5)  # max correspondence = factor x voxel
    icp_iterations: int = 15
    point_weight: float = 0.3  # weight of the point-to-point rows (they pin directions a plane leaves free)
    final_distance: float = 0.003  # m; inlier distance of the final score

    def __post_init__(self) -> None:
        lo, hi = self.yaw_range_deg
        if not (self.yaw_step_deg > 0 and hi > lo):
            raise ValueError(f"bad yaw sweep: step {self.yaw_step_deg}, range {self.yaw_range_deg}")
        if len(self.icp_voxels) != len(self.icp_corr_factor) or self.keep < 1:
            raise ValueError("icp_voxels and icp_corr_factor must pair up, and keep must be >= 1")


@dataclass
class TurnResult:
    """The best 4-DoF transform (source onto target) and how it was found."""

    T: np.ndarray
    yaw_deg: float  # about the axis, relative to the prior
    shift: np.ndarray  # (3,) m, translation after the yaw, in the input frame
    fitness: float  # at final_distance
    rmse: float
    color_fitness: float
    sweep: list[tuple[float, float]] = field(default_factory=list)  # (yaw, score) of every hypothesis

    def score(self, color_weight: float = 0.5) -> float:
        return self.fitness + color_weight * self.color_fitness


def _axis_frame(axis: np.ndarray) -> np.ndarray:
    """3x3 rotation whose third column is ``axis`` (unit)."""
    z = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    a = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(a, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _rot_z(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class _Target:
    """The target in the local frame (z = axis, origin = centre) with its KD-tree, normals and colours."""

    def __init__(self, cloud: Cloud, R_f: np.ndarray, center: np.ndarray):
        self.xyz = (cloud.xyz.astype(np.float64) - center) @ R_f
        self.normals = cloud.normals.astype(np.float64) @ R_f
        self.rgb = chroma(cloud.rgb)
        self.tree = cKDTree(self.xyz)


def chroma(rgb: np.ndarray) -> np.ndarray:
    """(N, 4): ``chromaticity`` r, g, b (summing to 1) and log-brightness, for shading-tolerant colour checks."""
    s = np.asarray(rgb, dtype=np.float64).reshape(-1, 3).sum(axis=1) + 3.0  # the brightness chromaticity divides by
    return np.column_stack([chromaticity(rgb), np.log(s)])


def _score(src_xyz: np.ndarray, src_rgb: np.ndarray, tgt: _Target, distance: float, tol: float,
           ratio: float = 2.0) -> tuple[float, float, float]:
    """(fitness, inlier rmse, colour fitness) of source points already in the target's local frame;
    ``src_rgb`` is ``chroma`` of the source colours."""
    d, j = tgt.tree.query(src_xyz, k=1, distance_upper_bound=distance)
    inl = np.isfinite(d)
    n = len(src_xyz)
    if n == 0 or not inl.any():
        return 0.0, np.inf, 0.0
    a, b = src_rgb[inl], tgt.rgb[j[inl]]
    agree = (np.abs(a[:, :3] - b[:, :3]).sum(axis=1) <= tol) & (np.abs(a[:, 3] - b[:, 3]) <= np.log(ratio))
    return float(inl.sum()) / n, float(np.sqrt(np.mean(d[inl] ** 2))), float(agree.sum()) / n


def icp_4dof(src: np.ndarray, tgt: _Target, theta: float, t: np.ndarray, max_corr: float, iterations: int,
             point_weight: float, fixed_yaw: bool = False) -> tuple[float, np.ndarray]:
    """4-DoF ICP in the local frame: source points ``src`` (N, 3) moved by Rz(theta), t onto the target.

    Each iteration linearises the yaw and solves the weighted least squares of point-to-plane residuals
    plus ``point_weight`` x point-to-point residuals for (dtheta, dtx, dty, dtz); ``fixed_yaw`` solves
    the shift only (the sweep: each hypothesis keeps its yaw).
    """
    t = np.asarray(t, dtype=float).copy()
    for _ in range(iterations):
        p = src @ _rot_z(theta).T + t
        d, j = tgt.tree.query(p, k=1, distance_upper_bound=max_corr)
        ok = np.isfinite(d)
        if ok.sum() < 10:
            break
        p, q, n = p[ok], tgt.xyz[j[ok]], tgt.normals[j[ok]]
        # d(Rz(dθ) p)/dθ at 0 = (-p_y, p_x, 0), rotation about the local origin (the centre)
        dp = np.column_stack([-p[:, 1], p[:, 0], np.zeros(len(p))])
        r_pl = np.einsum("ij,ij->i", p - q, n)
        A_pl = np.column_stack([np.einsum("ij,ij->i", dp, n), n])
        rows = [A_pl]
        rhs = [-r_pl]
        w = point_weight
        for k in range(3):
            e = np.zeros(3)
            e[k] = 1.0
            rows.append(w * np.column_stack([dp[:, k], np.tile(e, (len(p), 1))]))
            rhs.append(-w * (p[:, k] - q[:, k]))
        A, b = np.vstack(rows), np.concatenate(rhs)
        if fixed_yaw:
            x, *_ = np.linalg.lstsq(A[:, 1:], b, rcond=None)
            dth, dt = 0.0, x
        else:
            x, *_ = np.linalg.lstsq(A, b, rcond=None)
            dth, dt = float(x[0]), x[1:]
        # compose: new = Rz(dθ) (Rz(θ) s + t) + dt
        theta += dth
        t = _rot_z(dth) @ t + dt
        if abs(dth) < 1e-5 and np.linalg.norm(dt) < 1e-6:
            break
    return theta, t


def search_turn(source: Cloud, target: Cloud, axis: np.ndarray, center: np.ndarray,
                prior: np.ndarray | None = None, config: TurnSearchConfig | None = None) -> TurnResult:
    """Best yaw (about ``axis`` through ``center``) + shift mapping ``source`` (after ``prior``) onto ``target``."""
    cfg = config or TurnSearchConfig()
    prior = np.eye(4) if prior is None else np.asarray(prior, dtype=float)
    center = np.asarray(center, dtype=float).reshape(3)
    R_f = _axis_frame(axis)
    src0 = source.transformed(prior)

    def local(cloud: Cloud) -> np.ndarray:
        return (cloud.xyz.astype(np.float64) - center) @ R_f

    coarse_s, coarse_t = src0.downsampled(cfg.sweep_voxel), target.downsampled(cfg.sweep_voxel)
    tgt = _Target(coarse_t, R_f, center)
    s_xyz, s_rgb = local(coarse_s), chroma(coarse_s.rgb)
    lo, hi = cfg.yaw_range_deg
    yaws = np.arange(lo, hi, cfg.yaw_step_deg)
    sweep, starts = [], []
    for yaw in yaws:
        th, t = icp_4dof(s_xyz, tgt, np.radians(yaw), np.zeros(3), cfg.sweep_shift_corr, cfg.sweep_shift_iterations,
                         cfg.point_weight, fixed_yaw=True)
        f, _, cf = _score(s_xyz @ _rot_z(th).T + t, s_rgb, tgt, cfg.score_distance, cfg.color_tolerance,
                           cfg.brightness_ratio)
        sweep.append((float(yaw), f + cfg.color_weight * cf))
        starts.append((th, t))
    # best few hypotheses, at least 3 steps apart (neighbours of a peak are the same basin)
    order = sorted(range(len(sweep)), key=lambda i: -sweep[i][1])
    picked: list[int] = []
    for i in order:
        if all(min(abs(i - k), len(yaws) - abs(i - k)) >= 3 for k in picked):
            picked.append(i)
        if len(picked) == cfg.keep:
            break
    levels = []
    for v, k in zip(cfg.icp_voxels, cfg.icp_corr_factor, strict=True):
        s_l = src0.downsampled(v)
        levels.append((local(s_l), _Target(target.downsampled(v), R_f, center), k * v))
    fin_s, fin_rgb = levels[-1][0], chroma(src0.downsampled(cfg.icp_voxels[-1]).rgb)
    best = None
    for i in picked:
        theta, t = starts[i]
        for s_l, t_l, corr in levels:
            theta, t = icp_4dof(s_l, t_l, theta, t, corr, cfg.icp_iterations, cfg.point_weight)
        f, rmse, cf = _score(fin_s @ _rot_z(theta).T + t, fin_rgb, levels[-1][1], cfg.final_distance,
                             cfg.color_tolerance, cfg.brightness_ratio)
        key = f + cfg.color_weight * cf
        if best is None or key > best[0]:
            best = (key, theta, t, f, rmse, cf)
    assert best is not None
    _, theta, t, f, rmse, cf = best
    # back to the input frame: x -> R_f (Rz (R_f^T (x - c)) + t) + c, after the prior
    R = R_f @ _rot_z(theta) @ R_f.T
    T_local = make_transform(R, center - R @ center + R_f @ t)
    T = T_local @ prior
    yaw = float((np.degrees(theta) + 180.0) % 360.0 - 180.0)
    return TurnResult(T=T, yaw_deg=yaw, shift=R_f @ t, fitness=f, rmse=rmse, color_fitness=cf, sweep=sweep)


def project_to_turn(T: np.ndarray, axis: np.ndarray, center: np.ndarray) -> np.ndarray:
    """The 4-DoF transform nearest ``T``: its yaw about ``axis`` (tilt dropped), moving ``center`` where
    ``T`` moves it."""
    c = np.asarray(center, dtype=float).reshape(3)
    R = rotation_about_axis(axis, np.radians(yaw_deg_about(axis, T[:3, :3])))
    return make_transform(R, T[:3, :3] @ c + T[:3, 3] - R @ c)


def refine_turn(source: Cloud, target: Cloud, axis: np.ndarray, center: np.ndarray, T_init: np.ndarray,
                config: TurnSearchConfig | None = None) -> TurnResult:
    """4-DoF ICP (yaw + shift) from ``T_init`` projected to 4-DoF: a pair result without tilt."""
    cfg = config or TurnSearchConfig()
    center = np.asarray(center, dtype=float).reshape(3)
    prior = project_to_turn(np.asarray(T_init, dtype=float), axis, center)
    R_f = _axis_frame(axis)
    src0 = source.transformed(prior)
    theta, t = 0.0, np.zeros(3)
    tgt = None
    for v, k in zip(cfg.icp_voxels[1:], cfg.icp_corr_factor[1:], strict=True):
        tgt = _Target(target.downsampled(v), R_f, center)
        s_l = (src0.downsampled(v).xyz.astype(np.float64) - center) @ R_f
        theta, t = icp_4dof(s_l, tgt, theta, t, k * v, cfg.icp_iterations, cfg.point_weight)
    fin = src0.downsampled(cfg.icp_voxels[-1])
    f, rmse, cf = _score(((fin.xyz.astype(np.float64) - center) @ R_f) @ _rot_z(theta).T + t, chroma(fin.rgb), tgt,
                         cfg.final_distance, cfg.color_tolerance, cfg.brightness_ratio)
    R = R_f @ _rot_z(theta) @ R_f.T
    T = make_transform(R, center - R @ center + R_f @ t) @ prior
    return TurnResult(T=T, yaw_deg=float(np.degrees(theta)), shift=R_f @ t, fitness=f, rmse=rmse, color_fitness=cf)


def known_turn(axis: np.ndarray, center: np.ndarray, yaw_deg: float, shift: np.ndarray) -> np.ndarray:
    """The 4x4 of a yaw about ``axis`` through ``center`` followed by ``shift`` (a turn prior from a known yaw)."""
    R = rotation_about_axis(axis, np.radians(yaw_deg))
    c = np.asarray(center, dtype=float)
    return make_transform(R, c - R @ c + np.asarray(shift, dtype=float))
