"""One definition of a view: a static result gives the same dynamic view in process (``reconstruct``, import,
benchmarks) and after the wire and the session folder (a live scan, the incremental model, replay).

The view's centre matters: the dynamic stage stacks the views on it and ``pair.crop_to_overlap`` projects the
unit-sphere crop from it. It is the object body's centre, the static stage's footprint centre lifted by half
the object's height along the table normal, on every path.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from common.messages import Plane, PointCloud
from services.registration.api import view_center, view_from_result, view_from_static, view_result
from services.session_store import SessionStore


def static_result(rng: np.random.Generator) -> SimpleNamespace:
    """What the dynamic stage reads of a ``StaticViewResult``: a tilted table, an object standing on it."""
    normal = np.array([0.05, -0.03, 1.0])
    normal /= np.linalg.norm(normal)
    xyz = (rng.normal(size=(400, 3)) * [0.03, 0.03, 0.06] + [0.4, 0.1, 0.06]).astype(np.float32)
    nrm = rng.normal(size=(400, 3))
    cloud = PointCloud(xyz=xyz, rgb=rng.integers(0, 255, (400, 3), dtype=np.uint8),
                       normals=(nrm / np.linalg.norm(nrm, axis=1, keepdims=True)).astype(np.float32))
    table = Plane(normal=normal, offset=-0.01, center=np.array([0.4, 0.1, 0.01]))
    return SimpleNamespace(object_cloud=cloud, table=table,
                           object_center=np.array([0.4, 0.1, 0.012]), object_height=0.123,
                           scans=[SimpleNamespace(T_base_camera=np.eye(4))], to_json=dict)


def test_the_view_centre_is_the_body_centre():
    n = np.array([0.0, 0.0, 1.0])
    assert np.allclose(view_center([0.4, 0.1, 0.0], n, 0.2), [0.4, 0.1, 0.1])


def test_a_live_view_is_the_view_reconstruct_makes_of_the_same_result(tmp_path):
    result = static_result(np.random.default_rng(0))
    offline = view_from_static(result, 30.0, index=1)
    store = SessionStore(tmp_path / "session")  # the live path: the wire form, saved and loaded by the orchestrator
    store.save_view(view_result(1, result))
    live = view_from_result(store.load_view(1), 30.0, 1)
    assert np.array_equal(live.center, offline.center)
    assert np.allclose(live.center, result.object_center + 0.5 * result.object_height * result.table.normal)
    for field in ("xyz", "rgb", "normals"):
        assert np.array_equal(getattr(live, field), getattr(offline, field)), field
    assert np.array_equal(live.table.normal, offline.table.normal) and live.table.offset == offline.table.offset
    assert (live.commanded_turn_deg, live.index) == (offline.commanded_turn_deg, offline.index)
