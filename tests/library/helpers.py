"""Small synthetic models for library tests: surfaces with known shape, colors and point counts."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import open3d as o3d

from services.library.descriptors import DescriptorConfig
from services.library.store import ModelLibrary

#: Cheap descriptors so tests that only exercise storage stay fast.
FAST_DESCRIPTORS = DescriptorConfig(views=4, max_points=2000)


class CrashingLibrary(ModelLibrary):
    """A library that calls ``at_stage(stage)`` as an add or delete passes each of its named stages
    (``ADD_STAGES`` / ``DELETE_STAGES``): raising there, or killing the process there, is a crash at that
    point."""

    def __init__(self, root: str | Path, at_stage: Callable[[str], None], **kwargs) -> None:
        self.at_stage = at_stage
        super().__init__(root, **kwargs)

    def _passed(self, stage: str) -> None:
        self.at_stage(stage)


def box_surface(size=(0.06, 0.04, 0.12), n: int = 3000, seed: int = 0, color=(200, 30, 30)
                ) -> o3d.geometry.PointCloud:
    """``n`` points uniformly on the surface of an axis-aligned box standing on z = 0, one color."""
    rng = np.random.default_rng(seed)
    sx, sy, sz = size
    areas = np.array([sy * sz, sy * sz, sx * sz, sx * sz, sx * sy, sx * sy])
    face = rng.choice(6, n, p=areas / areas.sum())
    u, v = rng.random(n), rng.random(n)
    pts = np.zeros((n, 3))
    for f, (axis, side) in enumerate([(0, 0), (0, 1), (1, 0), (1, 1), (2, 0), (2, 1)]):
        m = face == f
        others = [a for a in range(3) if a != axis]
        pts[m, axis] = side * size[axis]
        pts[m, others[0]] = u[m] * size[others[0]]
        pts[m, others[1]] = v[m] * size[others[1]]
    pts -= [sx / 2, sy / 2, 0.0]
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pcd.colors = o3d.utility.Vector3dVector(np.tile(np.asarray(color, float) / 255.0, (n, 1)))
    return pcd


def crash_child(root: str, op: str, stage: str, target: str | None = None) -> None:
    """Run an add (or a delete of ``target``) in this process and SIGKILL it when it reaches ``stage``.

    Runs in a child started by a multiprocessing ``forkserver`` (tests/library/test_crash_safety.py): a
    real kill, with no chance for ``finally`` blocks or SQLite to clean up.
    """
    import os
    import signal

    def hook(s: str) -> None:
        if s == stage:
            os.kill(os.getpid(), signal.SIGKILL)

    lib = CrashingLibrary(root, hook, descriptor_config=FAST_DESCRIPTORS)
    if op == "add":
        lib.add(box_surface(seed=5), {"object_name": "killed", "quality": {"chamfer_mm": 2.5}})
    else:
        lib.delete(str(target))
