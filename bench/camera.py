"""``objscan bench camera``: one 640x480 capture through the services, against the twin's render alone.

- ``capture_ms_median``: a ``camera/capture`` request from another process: the camera service (sim
  backend) asks the sim service to render, validates and replies — the full round trip over Zenoh.
- ``render_ms_median``: the twin's ``World.render_frame`` called in this process on the same poses: the
  floor the service path is compared with (``service_vs_render_ratio``), measured in the same run.
- In-process figures of every backend (software RealSense, .db3 playback, session replay) come from
  ``bench/camera_backends.py``.
Target: ``capture_ms_median`` <= 100 ms on this machine.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np

from common import keys
from common.api import CaptureRequest
from common.client import request_sync
from common.launcher import ProcessSpec, ServiceGroup
from common.messages import JointState
from services.orchestrator.planning import camera_pose_looking_at


def _poses(n: int) -> list[np.ndarray]:
    target = np.array([0.6, 0.0, 0.09])
    return [camera_pose_looking_at(target, 0.38, 45.0, 180.0 + a) for a in np.linspace(-20, 20, n)]


def service_figures(n: int) -> dict[str, Any]:
    from common.messages import d435_intrinsics
    from services.sim.world import World, default_object_pose

    world = World("milk", profile="ideal", seed=0, object_pose=default_object_pose(0.6, 0.0))
    intr = d435_intrinsics(640, 480)
    capture, render = [], []
    with ServiceGroup() as group:
        group.launch([ProcessSpec("services.sim", ["--object", "milk"], service="sim"),
                      ProcessSpec("services.camera", ["--backend", "sim"], service="camera")], timeout=180)
        s = group.session
        request_sync(s, keys.sim(keys.DEFAULT_ROBOT, "world"),
                     __import__("common.messages", fromlist=["Request"]).Request(
                         params={"op": "reset", "object": "milk", "x": 0.6, "y": 0.0}), timeout=60)
        for i, T in enumerate(_poses(n + 3)):
            request_sync(s, keys.sim(keys.DEFAULT_ROBOT, "joints"),
                         JointState(names=[], position=np.zeros(0), T_base_camera=T), timeout=10)
            t0 = time.perf_counter()
            frame = request_sync(s, keys.camera_capture(keys.DEFAULT_ROBOT), CaptureRequest(), timeout=30)
            t1 = time.perf_counter()
            world.render_frame(T, intr, i)
            t2 = time.perf_counter()
            assert frame.depth.shape == (480, 640)
            if i >= 3:  # the first captures build the ray-casting scene
                capture.append((t1 - t0) * 1e3)
                render.append((t2 - t1) * 1e3)
    cap, ren = statistics.median(capture), statistics.median(render)
    return {"capture_ms_median": cap, "render_ms_median": ren, "service_vs_render_ratio": cap / ren,
            "captures": len(capture)}


def run(quick: bool = False) -> dict[str, Any]:
    from bench.camera_backends import run as backend_run

    figures = service_figures(10 if quick else 40)
    figures["backends"] = backend_run(quick=True)
    figures["targets"] = {"capture_ms_median": 100.0}
    return figures
