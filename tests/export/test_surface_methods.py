"""Both surface methods on a ray-cast session of an object with a recessed top (a can's lid inside its rim):
the TSDF fusion of the frames closes a surface, and the pocket is meshed as it is, not domed over by
normals turned inward."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from services.export import export_session
from services.export.surface import SurfaceConfig
from tests.export.synthetic_session import make_box_session, recessed_box_mesh

RECESSED = (0.08, 0.06, 0.10)
RIM_M, RECESS_M = 0.01, 0.015
CONFIG = SurfaceConfig(target_triangles=4000)
#: The surface is under test, not the collision parts: the hull is accepted, no decomposition runs.
ANY_PARTS = {"tolerance_m": 1.0}


def stl(out, name="synthetic_box"):  # noqa: ANN001, ANN201
    import trimesh

    return trimesh.load(out / f"{name}.stl")


@pytest.fixture(scope="module")
def recessed_session(tmp_path_factory):
    root = tmp_path_factory.mktemp("recessed")
    mesh = recessed_box_mesh(RECESSED, RIM_M, RECESS_M)
    session, _ = make_box_session(root / "session", size=RECESSED, mesh=mesh, cameras=12)
    return session, mesh


@pytest.mark.parametrize("method", ["poisson", "tsdf"])
def test_a_recessed_top_stays_a_pocket(recessed_session, tmp_path, method):
    session, true_mesh = recessed_session
    export_session(session, tmp_path / "out", method=method, config=CONFIG, texture=False, formats=("stl",),
                   evaluate=False, **ANY_PARTS)
    mesh = stl(tmp_path / "out")
    true_volume = float(np.prod(RECESSED)) - (RECESSED[0] - 2 * RIM_M) * (RECESSED[1] - 2 * RIM_M) * RECESS_M
    assert mesh.is_watertight
    assert mesh.volume == pytest.approx(true_volume, rel=0.04 if method == "poisson" else 0.08)
    assert mesh.bounds[1][2] < RECESSED[2] + 0.002  # nothing domes above the rim
    # straight down onto the middle of the pocket: its floor, not a lid over the rim
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(np.asarray(mesh.vertices, dtype=np.float32), np.asarray(mesh.faces, dtype=np.uint32))
    top = RECESSED[2] + 0.05
    rays = np.array([[x, y, top, 0, 0, -1] for x in (-0.01, 0.0, 0.01) for y in (-0.005, 0.0, 0.005)],
                    dtype=np.float32)
    hit_z = top - scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    assert np.all(np.abs(hit_z - (RECESSED[2] - RECESS_M)) < 0.003), hit_z


def test_the_same_points_give_the_same_surface(recessed_session):
    """Poisson's parallel solve added its threads' sums in varying order: the same session gave a slightly
    different mesh each run, and CoACD's parts of it differed by millimetres and by seconds of CPU."""
    from services.export.surface import poisson_surface

    _, true_mesh = recessed_session
    pcd = true_mesh.sample_points_uniformly(30000, use_triangle_normal=True)
    xyz, normals = np.asarray(pcd.points), np.asarray(pcd.normals)
    meshes = [poisson_surface(xyz, normals, None, CONFIG, oriented=True) for _ in range(3)]
    for m in meshes[1:]:
        assert np.array_equal(np.asarray(m.vertices), np.asarray(meshes[0].vertices))
        assert np.array_equal(np.asarray(m.triangles), np.asarray(meshes[0].triangles))
