"""``objscan bench soak``: many consecutive requests through the real services; memory and latency over time.

The cell (sim, camera, arm, registration; sim backends) runs as separate processes on loopback. The arm
moves the camera to the three scan poses of the orchestrator's first candidate set and keeps those three
frames; then

- ``captures`` (200; quick: 30) ``camera/capture`` requests, one after the other;
- ``registrations`` (50; quick: 6) ``registration/static`` requests on the three frames.

Every request has a timeout (capture 30 s, registration 300 s); a request that times out or fails is
counted (``timeouts``, ``errors``) and the soak goes on: nothing can hang it. The RSS of each service
process (``VmRSS`` in ``/proc/<pid>/status``) is sampled every 10 requests.

Figures:
- ``rss_growth_mb``: the largest growth of any service's RSS from its baseline (sampled after a warm-up of
  10 captures and 2 registrations, measured in the same run) to the end; ``rss_growth_ratio`` is that
  growth over the baseline; per service under ``services``. Bound: ``RSS_BOUND_MB`` (50 MB) per service.
- ``latency_ms_p50`` / ``latency_ms_p99``: capture round trips; ``static_latency_ms_p50``/``_p99``: static
  registrations; ``latency_drift_ratio``: median of the last tenth of captures over the first tenth.
"""

from __future__ import annotations

import os
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from common import keys
from common.api import CaptureRequest, MoveRequest, StaticRequest, ViewResult
from common.client import request_sync
from common.errors import ObjscanError, RequestTimeout
from common.launcher import ServiceGroup
from common.messages import RGBDFrame
from services.cell import cell_specs
from services.orchestrator.config import ScanGeometry
from services.orchestrator.planning import scan_pose_candidates

RSS_BOUND_MB = 50.0
SERVICES = ["sim", "camera", "arm", "registration"]
CAPTURE_TIMEOUT_S = 30.0
STATIC_TIMEOUT_S = 300.0
ROBOT = keys.DEFAULT_ROBOT


def rss_mb(pid: int) -> float:
    """Resident set size of a process in MB, from /proc (0 when the process is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


class Soak:
    """Runs the request streams and keeps every figure."""

    def __init__(self, group: ServiceGroup):
        self.group = group
        self.samples: dict[str, list[tuple[int, float]]] = {s: [] for s in SERVICES}
        self.requests = 0
        self.timeouts = 0
        self.errors: dict[str, int] = {}

    def sample_rss(self) -> None:
        for s in SERVICES:
            self.samples[s].append((self.requests, rss_mb(self.group.procs[s].pid)))

    def call(self, key: str, msg: Any, timeout: float) -> tuple[Any, float]:
        """One request with its timeout; failures are counted, never raised."""
        t0 = time.perf_counter()
        try:
            reply = request_sync(self.group.session, key, msg, timeout=timeout)
        except RequestTimeout:
            self.timeouts += 1
            reply = None
        except ObjscanError as exc:
            self.errors[exc.code] = self.errors.get(exc.code, 0) + 1
            reply = None
        self.requests += 1
        if self.requests % 10 == 0:
            self.sample_rss()
        return reply, (time.perf_counter() - t0) * 1e3

    def scan_frames(self) -> list[RGBDFrame]:
        """Three frames from the first reachable set of scan poses (as the orchestrator chooses them)."""
        for candidate in scan_pose_candidates(np.array([0.6, 0.0, 0.0]), 0.18, ScanGeometry()):
            try:
                for T in candidate:
                    request_sync(self.group.session, keys.arm(ROBOT, "move"),
                                 MoveRequest(kind="pose", target=T, frame="camera", dry_run=True), timeout=60)
            except ObjscanError:
                continue
            frames = []
            for T in candidate:
                request_sync(self.group.session, keys.arm(ROBOT, "move"),
                             MoveRequest(kind="pose", target=T, frame="camera", speed_scale=1.0), timeout=120)
                frame = request_sync(self.group.session, keys.camera_capture(ROBOT), CaptureRequest(),
                                     timeout=CAPTURE_TIMEOUT_S)
                assert isinstance(frame, RGBDFrame)
                frames.append(frame)
            return frames
        raise RuntimeError("no reachable scan pose set")


def run(quick: bool = False) -> dict[str, Any]:
    n_captures, n_static = (30, 6) if quick else (200, 50)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    t_start = time.monotonic()
    with ServiceGroup() as group:
        group.launch(cell_specs(SERVICES), timeout=240)
        soak = Soak(group)
        frames = soak.scan_frames()
        capture_ms: list[float] = []
        static_ms: list[float] = []
        static_ok = 0
        warm_captures, warm_static = 10, 2
        for i in range(n_captures):
            reply, ms = soak.call(keys.camera_capture(ROBOT), CaptureRequest(), CAPTURE_TIMEOUT_S)
            if isinstance(reply, RGBDFrame):
                capture_ms.append(ms)
            if i + 1 == warm_captures:
                baseline_captures = {s: rss_mb(group.procs[s].pid) for s in SERVICES}
        request = StaticRequest(frames=frames, profile="default", view=0)
        for i in range(n_static):
            reply, ms = soak.call(keys.REGISTRATION_STATIC, request, STATIC_TIMEOUT_S)
            if isinstance(reply, ViewResult):
                static_ms.append(ms)
                static_ok += 1
            if i + 1 == warm_static:
                baseline_static = rss_mb(group.procs["registration"].pid)
        soak.sample_rss()
        end = {s: rss_mb(group.procs[s].pid) for s in SERVICES}
        alive = all(group.procs[s].poll() is None for s in SERVICES)
    baseline = dict(baseline_captures)
    baseline["registration"] = baseline_static  # the registration worker's baseline is after its warm-up
    per_service = {}
    for s in SERVICES:
        growth = end[s] - baseline[s]
        per_service[s] = {"rss_baseline_mb": round(baseline[s], 1), "rss_end_mb": round(end[s], 1),
                          "rss_growth_mb": round(growth, 1), "rss_peak_mb": round(max(v for _, v in soak.samples[s])
                                                                                  if soak.samples[s] else end[s], 1),
                          "rss_growth_ratio": round(growth / baseline[s], 4) if baseline[s] else None}
    growth_max = max(p["rss_growth_mb"] for p in per_service.values())
    worst = max(per_service, key=lambda s: per_service[s]["rss_growth_mb"])
    tenth = max(1, len(capture_ms) // 10)
    drift = (statistics.median(capture_ms[-tenth:]) / statistics.median(capture_ms[:tenth])) if capture_ms else None
    return {
        "captures": n_captures, "captures_ok": len(capture_ms),
        "static_registrations": n_static, "static_ok": static_ok,
        "timeouts": soak.timeouts, "errors": soak.errors, "services_alive": alive,
        "rss_growth_mb": round(growth_max, 1), "rss_growth_worst_service": worst,
        "rss_growth_ratio": per_service[worst]["rss_growth_ratio"], "rss_bound_mb": RSS_BOUND_MB,
        "rss_within_bound": growth_max <= RSS_BOUND_MB,
        "latency_ms_p50": round(_pct(capture_ms, 50), 1), "latency_ms_p99": round(_pct(capture_ms, 99), 1),
        "latency_ms_max": round(max(capture_ms), 1) if capture_ms else None,
        "latency_drift_ratio": round(drift, 3) if drift else None,
        "static_latency_ms_p50": round(_pct(static_ms, 50), 1), "static_latency_ms_p99": round(_pct(static_ms, 99), 1),
        "services": per_service,
        "rss_samples": {s: [(n, round(v, 1)) for n, v in soak.samples[s]] for s in SERVICES},
        "seconds": round(time.monotonic() - t_start, 1),
    }


def main() -> None:
    import json
    import sys

    result = run(quick="--quick" in sys.argv)
    print(f"{'figure':32s} value")
    for k, v in result.items():
        if k not in ("services", "rss_samples"):
            print(f"{k:32s} {v}")
    print(f"\n{'service':14s} {'baseline MB':>12s} {'end MB':>8s} {'growth MB':>10s} {'peak MB':>8s}")
    for s, p in result["services"].items():
        print(f"{s:14s} {p['rss_baseline_mb']:12.1f} {p['rss_end_mb']:8.1f} {p['rss_growth_mb']:10.1f} "
              f"{p['rss_peak_mb']:8.1f}")
    if "--json" in sys.argv:
        print(json.dumps(result))


if __name__ == "__main__":
    main()
