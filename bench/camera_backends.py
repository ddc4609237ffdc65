"""Camera benchmark (in-process): what one 640x480 capture costs in each backend.

``run(quick)`` returns one JSON-able dict; the lead's ``bench/camera.py`` / ``objscan bench camera`` can
wrap it (the over-Zenoh round trip is measured there). Figures:

- ``capture_ms_median``: sim backend + the digital twin's renderer called in-process (render + checks);
- ``render_ms_median``: the twin's ``World.render_frame`` alone: the baseline, same run;
- ``sim_overhead_ratio``: capture / render (what the camera layer adds);
- ``realsense_software_ms_median``: a software D435 streaming at 30 fps through the realsense backend
  (includes waiting for the next frame after dropping stale ones);
- ``realsense_playback_ms_median``: a ``.db3`` playback, per frame (align + copy);
- ``replay_ms_median``: a session folder replay, per frame (PNG decode + checks).
"""

from __future__ import annotations

import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from services.camera.intrinsics import d435_color_intrinsics


def _median_ms(fn: Callable[[], Any], n: int) -> float:
    times = []
    for _ in range(n):
        t = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t) * 1000.0)
    return round(statistics.median(times), 2)


def _sim_figures(n: int, workdir: Path) -> dict[str, Any]:
    from bench.scenario import camera_look_at, simulated_views, write_session
    from services.camera.replay import ReplayCamera, ReplayCameraConfig
    from services.camera.sim import SimCamera
    from services.sim.world import World

    world = World("milk", profile="ideal", seed=0)
    intr = d435_color_intrinsics(640, 480)
    eyes = [np.array([0.05 * np.cos(a), 0.05 * np.sin(a), 0.35]) for a in np.linspace(0, 6.28, n)]
    poses = [camera_look_at(e, np.array([0.36, 0.0, 0.1])) for e in eyes]
    current = {"T": poses[0]}

    def render(T, w, h):
        return world.render_frame(current["T"], d435_color_intrinsics(w, h))

    world.render_frame(poses[0], intr)  # warm the mesh cache
    render_times, capture_times = [], []
    with SimCamera(render_request=render) as cam:
        for T in poses:  # interleaved on the same poses, so load on the machine hits both alike
            current["T"] = T.copy()  # a distinct array: no cache keyed on the object can help
            t0 = time.perf_counter()
            world.render_frame(T, intr)
            t1 = time.perf_counter()
            cam.capture()
            t2 = time.perf_counter()
            render_times.append((t1 - t0) * 1000.0)
            capture_times.append((t2 - t1) * 1000.0)
    render_ms = round(statistics.median(render_times), 2)
    capture_ms = round(statistics.median(capture_times), 2)
    views = simulated_views("milk", views=1, scans_per_view=3, seed=0)
    write_session(workdir / "session", views)
    with ReplayCamera(ReplayCameraConfig(session_dir=workdir / "session", loop=True)) as cam:
        replay_ms = _median_ms(cam.capture, n)
    return {"capture_ms_median": capture_ms, "render_ms_median": render_ms,
            "sim_overhead_ratio": round(capture_ms / render_ms, 3), "replay_ms_median": replay_ms}


def _realsense_figures(n: int, workdir: Path) -> dict[str, Any]:
    from bench.software_d435 import SoftwareD435, SoftwareD435Spec, record_db3
    from services.camera.realsense import RealSenseCamera, RealSenseCameraConfig

    spec = SoftwareD435Spec()
    di, ci = spec.depth_intrinsics, spec.color_intrinsics
    rng = np.random.default_rng(0)
    depth = (800 + rng.integers(0, 50, (di.height, di.width))).astype(np.uint16)
    color = rng.integers(0, 255, (ci.height, ci.width, 3), dtype=np.uint8)
    sw = SoftwareD435(spec)
    with sw.streaming((depth, color)), \
            RealSenseCamera(RealSenseCameraConfig(warmup_frames=2), device=sw.device) as cam:
        live_ms = _median_ms(cam.capture, n)
    path = record_db3(workdir / "bench.db3", [(depth, color)] * n, spec)
    with RealSenseCamera(RealSenseCameraConfig(playback_file=str(path))) as cam:
        playback_ms = _median_ms(cam.capture, n)
    return {"realsense_software_ms_median": live_ms, "realsense_playback_ms_median": playback_ms}


def run(quick: bool = False) -> dict[str, Any]:
    """Measure every backend on 640x480 frames; ``quick`` takes fewer samples."""
    n = 5 if quick else 20
    out: dict[str, Any] = {"frames": n, "width": 640, "height": 480, "target_capture_ms": 100.0}
    with tempfile.TemporaryDirectory(prefix="objscan-bench-camera-") as tmp:
        try:
            out.update(_sim_figures(n, Path(tmp)))
        except ImportError as exc:  # the twin is another part; report rather than fail
            out["sim_error"] = f"digital twin not importable: {exc}"
        out.update(_realsense_figures(n, Path(tmp)))
    if "capture_ms_median" in out:
        out["meets_target"] = out["capture_ms_median"] <= out["target_capture_ms"]
    return out


def main() -> None:
    figures = run()
    width = max(len(k) for k in figures)
    for key, value in figures.items():
        print(f"{key:<{width}}  {value}")


if __name__ == "__main__":
    main()
