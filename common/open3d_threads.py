"""Bound Open3D's CPU threads, so that a seed gives bit-identical registrations.

Open3D 0.20 runs its parallel loops on oneAPI TBB, not OpenMP: ``OMP_NUM_THREADS`` has no effect on it, and
with more than one thread its reductions (the RGB-D odometry's normal equations, ICP's) add partial sums in
whatever order the threads finish. Measured on this project's scans: the same three frames registered
three times in one process with ``OMP_NUM_THREADS=1`` gave three scan poses differing in the last bits; a
physics session amplified such bits into a different grasp and a different set-down, and a session must be
deterministic for a seed. One thread makes every call reproducible.

The knob stays the project's one thread setting, ``OMP_NUM_THREADS`` (the launcher sets 1 for every service
process; docker-compose gives registration 2): its value is applied to Open3D too. More than one thread is
faster and no longer bit-reproducible.
"""

from __future__ import annotations

import os
import sys

#: Threads when ``OMP_NUM_THREADS`` is not set: reproducible by default.
DEFAULT_THREADS = 1


def open3d_thread_count(environ: dict[str, str] | None = None) -> int:
    """The thread count ``OMP_NUM_THREADS`` asks for (``DEFAULT_THREADS`` when unset or not a positive int)."""
    value = (os.environ if environ is None else environ).get("OMP_NUM_THREADS", "")
    try:
        n = int(value)
    except ValueError:
        return DEFAULT_THREADS
    return n if n >= 1 else DEFAULT_THREADS


def limit_open3d_threads(*, only_if_imported: bool = False) -> int | None:
    """Apply ``open3d_thread_count()`` to Open3D; returns the count, or None when Open3D is not used.

    ``only_if_imported``: do nothing in a process that has not imported Open3D (the service runtime calls
    it for every service; the arm and the camera should not pay Open3D's import for it).
    """
    if only_if_imported and "open3d" not in sys.modules:
        return None
    import open3d as o3d

    n = open3d_thread_count()
    o3d.utility.set_max_threads(n)
    return n
