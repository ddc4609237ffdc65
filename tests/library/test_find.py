"""``find`` recognises an object from one partial view among the 5 HOPE objects of shared/data.

The library holds each object's ground-truth surface (colored samples of the HOPE mesh, standing in the
twin's default pose). Each query is a real single view: the twin scans the object (3 scans, ideal
profile) standing turned by 100 deg and moved, and static registration isolates it, exactly what a view of
an acquisition gives. The right object must rank first, by a clear margin, though two pairs of HOPE
objects share their shape (milk / orange juice cartons, soup / sauce cans).
"""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from common.geometry import make_transform, rotation_about_axis
from services.library import BadModelInput, FindConfig, ModelLibrary, ModelMetadata
from tests.conftest import shared_data

HOPE = ("alphabet_soup", "cream_cheese", "milk", "orange_juice", "tomato_sauce")


@pytest.fixture(scope="module")
def hope_library(tmp_path_factory):
    shared_data("hope")
    from services.sim.catalogue import hope_names, load_object
    from services.sim.world import default_object_pose

    missing = sorted(set(HOPE) - set(hope_names()))
    if missing:
        pytest.skip(f"HOPE objects missing from shared/data/hope: {missing}")
    lib = ModelLibrary(tmp_path_factory.mktemp("hope") / "lib")
    T = default_object_pose()
    ids = {}
    for name in HOPE:
        pts, rgb = load_object(name).gt_colored_points(20000, 1)
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts @ T[:3, :3].T + T[:3, 3]))
        pcd.colors = o3d.utility.Vector3dVector(rgb / 255.0)
        ids[name] = lib.add(pcd, ModelMetadata(object_name=name, source="ground_truth"))
    return lib, ids


def partial_view(name: str, yaw_deg: float = 100.0, seed: int = 11):
    """One isolated view of ``name`` as an acquisition's static stage gives it (xyz, rgb in base)."""
    from bench.scenario import simulated_views
    from services.registration.api import register_view
    from services.sim.world import default_object_pose

    pose = default_object_pose() @ make_transform(rotation_about_axis([0, 0, 1], np.radians(yaw_deg)),
                                                  [0.02, -0.03, 0.0])
    frames = simulated_views(name, views=1, seed=seed, object_pose=pose)
    cloud = register_view(frames[0]).object_cloud
    return cloud.xyz, cloud.rgb


@pytest.mark.parametrize("name", HOPE)
def test_right_object_ranks_first_from_one_partial_view(hope_library, name):
    lib, ids = hope_library
    xyz, rgb = partial_view(name)
    matches = lib.find(xyz, top_k=3, rgb=rgb)
    assert len(matches) == 3
    best, second = matches[0], matches[1]
    assert best.id == ids[name], [(m.detail["object"], m.score) for m in matches]
    assert best.score > 3.0 * second.score
    assert best.detail["fitness"] > 0.9 and best.detail["coverage"] > 0.8
    assert best.detail["descriptor_rank"] <= FindConfig().shortlist
    # the pose found maps the view onto the model: most query points land on it
    assert np.asarray(best.detail["T_model_query"]).shape == (4, 4)
    assert [m.score for m in matches] == sorted((m.score for m in matches), reverse=True)
    entry_id, score, detail = best  # the (id, score, detail) form
    assert entry_id == ids[name] and 0.0 < score <= 1.0 and detail["object"] == name


def test_find_on_empty_library_and_bad_queries(tmp_path):
    lib = ModelLibrary(tmp_path / "empty")
    assert lib.find(np.random.default_rng(0).random((500, 3)) * 0.1, top_k=3) == []
    with pytest.raises(BadModelInput):
        lib.find(np.full((500, 3), np.nan))
    with pytest.raises(BadModelInput):
        lib.find(np.zeros((5, 3)))
    with pytest.raises(BadModelInput):
        lib.find(np.zeros((500, 3)), top_k=0)
