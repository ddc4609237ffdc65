"""The scene interpreter's growing model: views placed by undoing their commanded turns."""

from __future__ import annotations

import numpy as np

from common.api import ViewResult
from common.geometry import rotation_about_line
from common.messages import Ok, Plane, PointCloud
from services.live import scene


def _box(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    p = rng.uniform(-1, 1, (3000, 3))
    k = rng.integers(0, 3, 3000)
    p[np.arange(3000), k] = np.sign(p[np.arange(3000), k])
    return p * (0.05, 0.03, 0.07) + (0.0, 0.0, 0.07)


def test_the_preview_grows_view_by_view_and_undoes_each_turn():
    table = Plane(normal=np.array([0.0, 0.0, 1.0]), offset=0.0, center=np.zeros(3))
    center0, center1 = np.array([0.40, 0.00, 0.07]), np.array([0.41, 0.01, 0.07])  # set down 1.4 cm away
    obj = _box(0)
    turn = 30.0
    T1 = rotation_about_line(np.array([0, 0, 1.0]), center1, np.radians(turn))
    view0 = obj + center0 - (0, 0, 0.07)
    view1 = (obj + center1 - (0, 0, 0.07)) @ T1[:3, :3].T + T1[:3, 3]  # the object turned by 30° in place
    s = scene.SceneInterpreter()
    s.sample(1.0, Ok(info={"state": "scan", "turns_deg": [0.0]}))

    def vr(k: int, xyz: np.ndarray, c: np.ndarray) -> ViewResult:
        return ViewResult(view=k, cloud=PointCloud(xyz=xyz.astype(np.float32)), table=table, center=c,
                          height=0.14, scan_poses=np.stack([np.eye(4)] * 3))

    ev0 = [e for e in s.exchange(2.0, "k", None, vr(0, view0, center0)) if isinstance(e, scene.ModelPreview)]
    assert ev0 and ev0[0].views == [0] and len(ev0[0].xyz) == 3000
    # view 1 arrives before the status that knows its turn: no preview of it yet, then it joins
    assert [e.views for e in s.exchange(3.0, "k", None, vr(1, view1, center1))
            if isinstance(e, scene.ModelPreview)] == [[0]]
    ev = [e for e in s.sample(4.0, Ok(info={"state": "scan", "turns_deg": [0.0, turn]}))
          if isinstance(e, scene.ModelPreview)]
    assert ev and ev[0].views == [0, 1]
    placed1 = ev[0].xyz[3000:]
    assert np.abs(placed1 - view0.astype(np.float32)).max() < 1e-5  # view 1 lands exactly on view 0
