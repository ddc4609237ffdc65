"""``python -m bench.reconstruct_odometry``: what a cheaper RGB-D odometry would save, and what it costs in trust.

The default profile's static stage spent about two thirds of its CPU in Open3D's legacy RGB-D odometry (two
calls per scan pair: the reverse seed pass at half resolution, then the forward pass at full resolution), so
it is where a speed-up would come from; the tensor backend now shipped cut that to about 40 %. The odometry is
also what pins plain symmetric objects (it sees the whole scene, table included): a cheaper setting that lands a
few millimetres off still passes the scan check and is fused. This bench runs the static stage (``register_view``
on every view, in this process, one thread) of ``bench reconstruct``'s sessions under each odometry setting, and
reports per object the worst scan pose error against the twin's truth (relative to scan 0,
``static_max_trans_err_mm``, as ``bench reconstruct``), the odometry's CPU seconds per scan pair and the stage's
CPU seconds.

Variants (``VARIANTS``):

* ``default``: the shipped setting (tensor odometry prepared as the legacy, ``static/tensor_odometry.py``; reverse
  seed at half resolution, forward (16, 16, 1)).
* ``legacy``: the same passes on Open3D's legacy odometry (``odometry_backend="legacy"``), the earlier default.
* ``half_resolution``: seed and forward both on half-resolution images, forward (16, 16): no full-resolution
  level.
* ``fine_only``: forward (0, 0, 1): the reverse seed, then only the full-resolution iteration.
* ``quarter_seed``: the reverse seed pass on quarter-resolution images (160 x 120), the forward as shipped.
* ``roi_window``: both passes on the view's images cut to the union of its scans' region-of-interest pixel
  boxes grown by 16 px (``odometry_window_margin``; the shipped setting runs them on the whole image).
* ``roi_window_48``: the same rectangle grown by 48 px.
* ``forward_16_8_1``: the forward pass with 8 iterations (not 16) at half resolution, its costliest coarse level.
* ``seed_16_8``: the reverse seed pass with 8 iterations (not 16) at its finer level (half resolution).

The rows other than ``default`` and ``legacy`` in docs/static-registration.md were measured on the legacy backend
(then the default); they now run on the tensor one.

Each variant is a ``StaticConfig`` of the public API (the benchmarks use registration through it only), so
what it measures is what a user would get from that setting. The tensor odometry with Open3D's own defaults is
not a setting of the static stage; its figures in docs/static-registration.md were measured by swapping the
default profile's odometry calls for it, with the same priors and iterations.

``--objects box,milk`` (default: every object of both sets), ``--variants default,fine_only`` (default: all),
``--views N`` (first N views of each session). Sessions are ``bench reconstruct``'s (recorded now, or reused
from ``$OBJSCAN_BENCH_SESSION_DIR``). CPU seconds are the thread's own, so they hold on a loaded machine.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from common.messages import RGBDFrame

#: Each variant's ``StaticConfig`` overrides (``default``: none).
VARIANTS: dict[str, dict[str, Any]] = {
    "default": {},
    "half_resolution": {"odometry_step": 2, "odometry_iterations": (16, 16), "odometry_seed_step": 1},
    "fine_only": {"odometry_iterations": (0, 0, 1)},
    "quarter_seed": {"odometry_seed_step": 4},
    "roi_window": {"odometry_window_margin": 16},
    "roi_window_48": {"odometry_window_margin": 48},
    "forward_16_8_1": {"odometry_iterations": (16, 8, 1)},
    "seed_16_8": {"odometry_seed_iterations": (16, 8)},
    "legacy": {"odometry_backend": "legacy"},
}


def measure_views(views: list[list[RGBDFrame]], cfg: Any, name: str) -> dict[str, Any]:
    """One object's static stage under variant ``name``: worst pose error, CPU, and how the scans went."""
    from services.registration.api import register_view, relative_pose_errors

    if name not in VARIANTS:
        raise ValueError(f"unknown odometry variant {name!r}; known: {', '.join(VARIANTS)}")
    errors, cpu, odometry, pairs, left_out, methods = [], 0.0, 0.0, 0, 0, {}
    config = cfg.with_(**VARIANTS[name])
    for frames in views:
        t = time.thread_time()
        result = register_view(frames, config)
        cpu += time.thread_time() - t
        odometry += result.cpu_timings.get("odometry", 0.0)
        errors.extend(e[0] for e in relative_pose_errors(result, frames) or [])
        for s in result.scans[1:]:
            pairs += 1
            left_out += not s.fused
            methods[s.method] = methods.get(s.method, 0) + 1
    return {
        "variant": name,
        "static_max_trans_err_mm": round(max(errors), 3) if errors else None,
        "scans_over_1mm": sum(e > 1.0 for e in errors),
        "scans_left_out": left_out,
        "odometry_cpu_s_per_pair": round(odometry / max(1, pairs), 4),
        "odometry_cpu_s": round(odometry, 3),
        "static_cpu_s": round(cpu, 3),
        "pairs": pairs,
        "methods": methods,
    }


def session_views(object_set: str, name: str, sessions: Path, limit: int | None) -> tuple[list[list[RGBDFrame]], Any]:
    """The object's ``bench reconstruct`` session as frames per view, and the static config ``reconstruct``
    would use for it (the session's stated pose accuracy)."""
    from bench.reconstruct import session_and_truth
    from common.pose_accuracy import session_pose_accuracy
    from common.session_folder import read_scan, read_session
    from services.registration.api import StaticConfig

    session = read_session(session_and_truth(object_set, name, sessions)[0])
    accuracy, source = session_pose_accuracy(session.data)
    cfg = StaticConfig().with_accuracy(accuracy if source == "session" else None)
    indices = [int(e["index"]) for e in session.views][:limit]
    return [[read_scan(session.path, k, j) for j in session.scans(k)] for k in indices], cfg


def run(objects: list[str] | None = None, variants: tuple[str, ...] = tuple(VARIANTS), views: int | None = None,
        say: Callable[[str], None] = print) -> dict[str, Any]:
    """Every (object, variant)'s figures, objects in ``bench reconstruct``'s order."""
    from bench.reconstruct import set_objects
    from common.open3d_threads import limit_open3d_threads

    limit_open3d_threads()
    pairs = [(s, n) for s, n in set_objects("all") if objects is None or n in objects]
    keep = os.environ.get("OBJSCAN_BENCH_SESSION_DIR")
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-odometry-") as tmp:
        sessions = Path(keep) if keep else Path(tmp)
        sessions.mkdir(parents=True, exist_ok=True)
        for object_set, name in pairs:
            frames, cfg = session_views(object_set, name, sessions, views)
            for v in variants:
                row = {"set": object_set, "object": name, **measure_views(frames, cfg, v)}
                say(f"{name} {v}: max {row['static_max_trans_err_mm']} mm, odometry "
                    f"{row['odometry_cpu_s_per_pair']} CPU-s/pair, static {row['static_cpu_s']} CPU-s")
                rows.append(row)
    return {"omp_num_threads": os.environ.get("OMP_NUM_THREADS", "unset"), "views": views, "objects": rows}


def main() -> None:
    import json

    args = sys.argv[1:]

    def value(flag: str) -> str | None:
        return args[args.index(flag) + 1] if flag in args[:-1] else None

    objects = value("--objects")
    variants = value("--variants")
    views = value("--views")
    figures = run(objects.split(",") if objects else None, tuple(variants.split(",")) if variants else tuple(VARIANTS),
                  int(views) if views else None)
    out = value("--json")
    if out:
        Path(out).write_text(json.dumps(figures, indent=1))


if __name__ == "__main__":
    main()
