"""``objscan bench transport``: codec cost against a plain copy, and request round trip between processes.

- ``codec_vs_copy_ratio``: (encode + decode of an 848x480 RGB-D frame) / (numpy copy of the same bytes),
  both measured here in the same run. Target <= 3.
- ``roundtrip_ms_median``: median time to request that frame from another process over Zenoh on
  loopback and decode it, through the router every objscan cell runs (client -> router -> service and back:
  two hops each way). Target <= 2 ms.
- ``roundtrip_direct_ms_median``: the same request between just the two processes, linked peer to peer
  (``OBJSCAN_ZENOH_MODE=peer``, the service listening, the caller connecting): the one-hop figure.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import replace
from typing import Any

import numpy as np

from bench.frame_server import FRAME_KEY, make_frame
from common.client import request_sync
from common.codec import decode, encode
from common.launcher import ProcessSpec, ServiceGroup
from common.memory import tune_malloc
from common.zenoh_config import ZenohSettings


def _median_ms(fn, repeats: int) -> float:  # noqa: ANN001
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def codec_figures(repeats: int) -> dict[str, float]:
    frame = make_frame()
    raw = np.concatenate([frame.color.ravel(), frame.depth.view(np.uint8).ravel()])
    payload = encode(frame)
    for _ in range(20):  # warm caches and allocators for both sides alike
        decode(encode(frame))
        raw.copy()
    codec = _median_ms(lambda: decode(encode(frame)), repeats)
    copy = _median_ms(raw.copy, repeats)
    return {"encode_decode_ms_median": codec, "numpy_copy_ms_median": copy,
            "codec_vs_copy_ratio": codec / copy, "frame_bytes": len(payload)}


def _request_times(group: ServiceGroup, repeats: int) -> list[float]:
    session = group.session
    for _ in range(10):
        request_sync(session, FRAME_KEY, timeout=10)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        request_sync(session, FRAME_KEY, timeout=10)
        times.append((time.perf_counter() - t0) * 1e3)
    return times


def roundtrip_figures(repeats: int) -> dict[str, float]:
    spec = ProcessSpec("bench.frame_server", ["--instance", "bench"], service="bench-frame")
    with ServiceGroup() as group:  # the cell's topology: every process a client of one router
        group.launch([spec])
        routed = _request_times(group, repeats)
    with ServiceGroup(start_router=False) as group:  # two processes, one peer link
        group.settings = ZenohSettings(mode="peer", connect=[group.endpoint])
        peer_env = {"OBJSCAN_ZENOH_MODE": "peer", "OBJSCAN_ZENOH_LISTEN": group.endpoint, "OBJSCAN_ZENOH_CONNECT": ""}
        group.start(replace(spec, env=peer_env))
        group.wait_listening(spec.label(), timeout=30)
        group.wait_alive(["bench-frame"], timeout=30)
        direct = _request_times(group, repeats)
    return {"roundtrip_ms_median": statistics.median(routed), "roundtrip_ms_p90": float(np.percentile(routed, 90)),
            "roundtrip_direct_ms_median": statistics.median(direct),
            "roundtrip_direct_ms_p90": float(np.percentile(direct, 90)), "roundtrip_samples": repeats}


def run(quick: bool = False) -> dict[str, Any]:
    tune_malloc()  # as every service process does (see common/memory.py)
    figures = codec_figures(200 if quick else 2000)
    figures.update(roundtrip_figures(50 if quick else 300))
    figures["targets"] = {"codec_vs_copy_ratio": 3.0, "roundtrip_ms_median": 2.0, "roundtrip_direct_ms_median": 2.0}
    return figures
