"""The export of a small ray-cast session: a closed mesh in the object frame, and assets that load as they are.

One export (module fixture) of a coloured box seen by a ring of cameras; the box's true size, pose and
inertia are known exactly, so every check compares with the truth, not with a stored result.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from services.export import ExportInputError, export_session
from services.export.surface import SurfaceConfig
from tests.export.synthetic_session import make_box_session

SIZE = (0.08, 0.05, 0.12)
YAW_DEG = 20.0
DENSITY = 800.0


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    root = tmp_path_factory.mktemp("export")
    session, T_true = make_box_session(root / "session", size=SIZE, yaw_deg=YAW_DEG)
    out = root / "out"
    result = export_session(session, out, density=DENSITY, config=SurfaceConfig(target_triangles=4000))
    return session, out, result, T_true


def true_box_inertia(mass: float) -> np.ndarray:
    sx, sy, sz = SIZE
    return mass / 12.0 * np.diag([sy ** 2 + sz ** 2, sx ** 2 + sz ** 2, sx ** 2 + sy ** 2])


def test_mesh_is_watertight_volume_in_object_frame(exported):
    import trimesh

    _, out, result, T_true = exported
    mesh = trimesh.load(out / "synthetic_box.stl")
    assert mesh.is_watertight and mesh.is_volume
    assert result["watertight"] and result["is_volume"]
    # the part of the wall clock spent waiting for a CPU on a shared machine
    assert 0.0 <= result["cpu_wait_seconds"] <= result["seconds"]
    assert mesh.volume == pytest.approx(np.prod(SIZE), rel=0.03)
    lo, hi = mesh.bounds
    assert lo[2] == pytest.approx(0.0, abs=1e-9)  # the bottom is the table plane
    # long side on x, footprint centred at the origin
    assert hi[0] - lo[0] == pytest.approx(SIZE[0], abs=0.003)
    assert hi[1] - lo[1] == pytest.approx(SIZE[1], abs=0.003)
    assert np.abs((hi[:2] + lo[:2]) / 2).max() < 0.002
    # the session keeps where the object frame is in base: the true pose up to the box's symmetry
    T = np.asarray(json.loads((exported[0] / "object_frame.json").read_text())["T_base_object"])
    assert np.linalg.norm(T[:2, 3] - T_true[:2, 3]) < 0.002
    assert abs(T[:3, 0] @ T_true[:3, 0]) > np.cos(np.radians(2.0))


def test_mjcf_rests_where_it_was_dropped(exported):
    mujoco = pytest.importorskip("mujoco")
    _, out, result, _ = exported
    spec = mujoco.MjSpec.from_file(str(out / "synthetic_box.xml"))
    floor = spec.worldbody.add_geom()
    floor.type = mujoco.mjtGeom.mjGEOM_PLANE
    floor.size = [1.0, 1.0, 0.1]
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qpos[2] = 0.01  # dropped from 1 cm above its standing pose
    mujoco.mj_forward(model, data)
    steps = int(round(2.0 / model.opt.timestep))
    for _ in range(steps):
        mujoco.mj_step(model, data)
    pos, quat = data.qpos[:3], data.qpos[3:7]
    assert np.linalg.norm(pos) < 0.005
    angle = 2 * np.degrees(np.arccos(min(1.0, abs(float(quat[0])))))
    assert angle < 3.0
    assert model.body_mass[1] == pytest.approx(result["inertial"]["mass_kg"], rel=1e-6)


def test_urdf_loads_with_an_independent_parser_and_inertia_is_the_box(exported):
    yourdfpy = pytest.importorskip("yourdfpy")
    _, out, result, _ = exported
    urdf = yourdfpy.URDF.load(str(out / "synthetic_box.urdf"), load_meshes=False, build_scene_graph=False)
    link = urdf.robot.links[0]
    I = np.asarray(link.inertial.inertia, dtype=float)
    assert np.all(np.linalg.eigvalsh(I) > 0)
    mass = float(link.inertial.mass)
    assert mass == pytest.approx(DENSITY * np.prod(SIZE), rel=0.05)
    true = true_box_inertia(DENSITY * np.prod(SIZE))
    assert np.allclose(np.diag(I), np.diag(true), rtol=0.10)
    assert len(link.collisions) == result["parts"] >= 1
    # a box is its own hull: one part, flush with the surface, no decomposition run
    assert result["parts_coacd"] == "not_needed" and result["parts"] == 1
    assert 0.0 <= result["parts_deviation_mm"]["p95"] <= result["parts_deviation_mm"]["max"] < 2.0
    for c in link.collisions:
        assert (out / c.geometry.mesh.filename).is_file()


def test_glb_opens_with_a_texture_image(exported):
    import trimesh

    _, out, result, _ = exported
    scene = trimesh.load(out / "synthetic_box.glb")
    geoms = list(scene.geometry.values()) if isinstance(scene, trimesh.Scene) else [scene]
    image = geoms[0].visual.material.baseColorTexture
    assert image is not None and min(image.size) >= 64
    assert result["textured"]
    # the faces' colours came from the images: the atlas holds the box's saturated face colours
    pixels = np.asarray(image.convert("RGB")).reshape(-1, 3).astype(int)
    saturated = (pixels.max(axis=1) - pixels.min(axis=1)) > 120
    assert saturated.mean() > 0.3


def test_density_and_mass_are_exclusive(tmp_path, exported):
    session = exported[0]
    with pytest.raises(ExportInputError) as err:
        export_session(session, tmp_path / "x", density=1000.0, mass=0.5)
    assert err.value.code == "bad_argument"


def test_session_without_model_is_a_typed_error(tmp_path):
    (tmp_path / "s").mkdir()
    (tmp_path / "s" / "session.json").write_text(json.dumps({"views": [{"index": 0}]}))
    with pytest.raises(ExportInputError) as err:
        export_session(tmp_path / "s", tmp_path / "out")
    assert err.value.code == "no_model"
