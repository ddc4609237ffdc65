"""What static registration returns for one view, and its JSON figures."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from common.geometry import transform_error
from common.messages import Plane, PointCloud

from .pairwise import PairResult


@dataclass
class ScanResult:
    """One scan's corrected pose and how it was obtained.

    ``path`` is ``anchor`` for scan 0 (its believed pose defines the view's frame), else ``local`` (ICP from
    the arm's pose passed the check), ``global`` (the default's search inside the plausible window won) or
    ``paper`` (paper profile). ``method`` says which step produced it. ``fitness``/``inlier_rmse`` are the
    pair check against scan 0 (default: 3 mm voxel clouds, 6 mm correspondence distance); ``verified`` is
    whether it passed, ``fused`` whether its points are in the view's cloud (a scan that failed its check or
    whose correction the arm's accuracy cannot explain never is; ``rejected`` says why).
    """

    index: int
    T_base_camera: np.ndarray  # corrected
    T_base_camera_believed: np.ndarray
    path: str
    method: str  # anchor | rgbd_odometry | icp (either + "+object_icp") | window_search+icp | paper
    fitness: float
    inlier_rmse: float
    verified: bool
    n_points: int
    fused: bool = True
    rejected: str | None = None  # why the scan was left out of the view (None: fused)

    def correction(self) -> tuple[float, float]:
        """(m, deg) between the believed and the corrected pose."""
        return transform_error(self.T_base_camera, self.T_base_camera_believed)

    def to_json(self) -> dict[str, Any]:
        dt, dr = self.correction()
        return {
            "index": self.index,
            "path": self.path,
            "verified": self.verified,
            "fused": self.fused,
            **({"rejected": self.rejected} if self.rejected else {}),
            "fitness": round(self.fitness, 4),
            "inlier_rmse_mm": round(self.inlier_rmse * 1e3, 3) if np.isfinite(self.inlier_rmse) else None,
            "correction_mm": round(dt * 1e3, 3),
            "correction_deg": round(dr, 4),
            "n_points": self.n_points,
            "T_base_camera": np.round(self.T_base_camera, 8).tolist(),
        }


@dataclass
class PairOutcome:
    """One registered pair, as a profile hands it to the shared flow: ``T`` maps source camera points into
    the target camera's frame; ``check`` is the pair's fitness / RMSE, ``verified`` whether it passed."""

    T: np.ndarray
    path: str  # "local" | "global" | "paper"
    method: str  # "rgbd_odometry" | "icp" (either + "+object_icp") | "window_search+icp" | "paper"
    check: PairResult
    verified: bool
    reason: str | None = None  # why it is not verified (implausible correction, poor fit); None when verified


@dataclass
class StaticViewResult:
    """Static registration and isolation of one view (all geometry in ``base``)."""

    object_cloud: PointCloud  # xyz float32, rgb uint8, normals float32
    table: Plane  # what the object stands on: the table, or a turntable's / platform's top (parallel to it)
    object_center: np.ndarray  # (3,) footprint centre on the table (or that top)
    object_height: float  # m above the table (or that top)
    scans: list[ScanResult]
    timings: dict[str, float]
    profile: str
    seed_point: np.ndarray | None  # first scan's centre-pixel point (the paper's "centre depth")
    scene_points: int = 0  # points of PC_global at the output voxel
    n_clusters: int = 0
    figures: dict[str, Any] = field(default_factory=dict)
    # CPU seconds of each step in the thread that ran the view ("odometry" is the part of "register" spent in
    # the local path's RGB-D odometry, its images included): the load-independent account of where the time
    # went, beside the wall ``timings``
    cpu_timings: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "profile": self.profile,
            "object_points": len(self.object_cloud),
            "scene_points": self.scene_points,
            "object_center": np.round(self.object_center, 6).tolist(),
            "object_height_m": round(self.object_height, 5),
            "table": {
                "normal": np.round(self.table.normal, 6).tolist(),
                "offset": round(self.table.offset, 6),
                "center": np.round(self.table.center, 6).tolist(),
            },
            "n_clusters": self.n_clusters,
            "seed_point": None if self.seed_point is None else np.round(self.seed_point, 6).tolist(),
            "scans": [s.to_json() for s in self.scans],
            "scans_left_out": [{"index": s.index, "reason": s.rejected} for s in self.scans if not s.fused],
            "timings_s": {k: round(v, 4) for k, v in self.timings.items()},
            "cpu_timings_s": {k: round(v, 4) for k, v in self.cpu_timings.items()},
            **self.figures,
        }


class Stopwatch:
    """Accumulates wall time and this thread's CPU time per named step (``with sw("register"): ...``).

    Thread CPU time, because views run in threads of one process: the process's CPU clock would charge a view
    with its neighbours' work. Open3D runs in the calling thread when bounded to one thread (the default)."""

    def __init__(self) -> None:
        self.times: dict[str, float] = {}
        self.cpu: dict[str, float] = {}
        self._t0, self._c0 = time.perf_counter(), time.thread_time()

    @contextmanager
    def __call__(self, name: str) -> Iterator[None]:
        t, c = time.perf_counter(), time.thread_time()
        try:
            yield
        finally:
            self.times[name] = self.times.get(name, 0.0) + time.perf_counter() - t
            self.cpu[name] = self.cpu.get(name, 0.0) + time.thread_time() - c

    def total(self) -> dict[str, float]:
        return {**self.times, "total": time.perf_counter() - self._t0}

    def cpu_total(self) -> dict[str, float]:
        return {**self.cpu, "total": time.thread_time() - self._c0}
