"""The renderer and the D435 model: depth where the geometry says, noise as the model says, colours from
the texture at the right pixels, reproducible for a seed."""

from __future__ import annotations

import numpy as np
import pytest

from common.geometry import invert, make_transform
from common.messages import d435_intrinsics
from services.sim.catalogue import load_object
from services.sim.errors import SimInputError
from services.sim.render import (
    LABEL_NONE,
    LABEL_OBJECT,
    LABEL_TABLE,
    Lighting,
    RenderScene,
    TableSpec,
    render,
)
from services.sim.sensor_model import D435Noise, depth_edges
from tests.sim.meshes import BOTTOM_LEFT, BOTTOM_RIGHT, TOP_LEFT, TOP_RIGHT, write_box_ply, write_textured_box_obj

K = d435_intrinsics(640, 480)
#: camera at the base origin looking along +x, image up = +z (optical: z forward, x right = -y, y down = -z)
R_LOOK_X = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
FLAT_LIGHT = Lighting(ambient=1.0, diffuse=0.0)


def rot_z(a: float) -> np.ndarray:
    return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])


def rot_x(a: float) -> np.ndarray:
    return np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])


def camera_looking_along_x(height: float = 0.0) -> np.ndarray:
    return make_transform(R_LOOK_X, [0.0, 0.0, height])


def wall_scene(tmp_path, distance: float) -> RenderScene:
    """A 2 m x 2 m wall facing the camera with its front face at ``distance`` along +x."""
    obj = load_object(str(write_box_ply(tmp_path, (0.05, 2.0, 2.0), name=f"wall{distance}")))
    # object frame: bottom centre at origin; the wall's -x face is at x = -0.025
    return RenderScene(obj, make_transform(translation=[distance + 0.025, 0.0, -1.0]), table=None)


def project(T_base_camera: np.ndarray, p_base: np.ndarray) -> tuple[int, int]:
    p = invert(T_base_camera)[:3, :3] @ p_base + invert(T_base_camera)[:3, 3]
    return int(round(K.fx * p[0] / p[2] + K.cx)), int(round(K.fy * p[1] / p[2] + K.cy))


def test_wall_depth_is_exact_without_noise(tmp_path):
    res = render(wall_scene(tmp_path, 0.8), camera_looking_along_x(), K, noise=None)
    assert res.depth.dtype == np.uint16 and res.color.dtype == np.uint8 and res.depth.shape == (480, 640)
    assert np.all(res.labels == LABEL_OBJECT)
    np.testing.assert_allclose(res.depth_true, 0.8, atol=1e-5)  # z-depth, not ray length
    assert np.all(res.depth == 800)


@pytest.mark.parametrize("distance", [0.6, 1.5])
def test_wall_depth_error_follows_the_stereo_model(tmp_path, distance):
    noise = D435Noise(dropout_prob=0.0)
    res = render(wall_scene(tmp_path, distance), camera_looking_along_x(), K, noise=noise,
                 rng=np.random.default_rng(4))
    valid = res.depth > 0
    assert valid.mean() > 0.99
    err = res.depth[valid] * 0.001 - distance
    sigma_z = noise.depth_sigma(distance, K.fx)  # z^2 * subpixel / (f * b)
    expected = np.sqrt(sigma_z**2 + 0.001**2 / 12)  # plus 1 mm quantisation
    assert abs(err.mean()) < 0.15 * expected + 1e-4
    assert err.std() == pytest.approx(expected, rel=0.15)
    assert np.mean(np.abs(err) > 4.5 * expected + 0.0005) < 1e-3


def test_noise_grows_with_z_squared(tmp_path):
    noise = D435Noise(dropout_prob=0.0)
    stds = []
    for d in (0.8, 2.0):
        res = render(wall_scene(tmp_path, d), camera_looking_along_x(), K, noise=noise, rng=np.random.default_rng(1))
        stds.append(np.std(res.depth[res.depth > 0] * 0.001))
    assert stds[1] / stds[0] == pytest.approx((2.0 / 0.8) ** 2, rel=0.2)


def test_no_depth_outside_the_sensor_range(tmp_path):
    for d in (0.25, 3.2):
        res = render(wall_scene(tmp_path, d), camera_looking_along_x(), K, noise=D435Noise.noiseless(),
                     rng=np.random.default_rng(0))
        assert res.depth.max() == 0, d
        assert res.labels[240, 320] == LABEL_OBJECT  # the ground truth still knows the wall is there


def test_flying_pixels_and_dropouts_only_at_depth_edges(tmp_path):
    """A box 0.6 m away in front of a wall at 1.2 m: edge pixels blend or drop, interior pixels never."""
    import open3d as o3d

    wall = load_object(str(write_box_ply(tmp_path, (0.05, 3.0, 3.0), name="w")))
    box = load_object(str(write_box_ply(tmp_path, (0.1, 0.2, 0.2), name="b")))
    merged = o3d.geometry.TriangleMesh(wall.mesh).translate((1.225, 0, -1.5))
    merged += o3d.geometry.TriangleMesh(box.mesh).translate((0.65, 0, -0.1))
    o3d.io.write_triangle_mesh(str(tmp_path / "m.ply"), merged)
    both = load_object(str(tmp_path / "m.ply"))  # re-centred on its footprint: put it back where it was
    lo = np.asarray(merged.vertices).min(axis=0)
    hi = np.asarray(merged.vertices).max(axis=0)
    scene = RenderScene(both, make_transform(translation=[(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]]),
                        table=None)
    noise = D435Noise(dropout_prob=0.0, subpixel=0.0)
    res = render(scene, camera_looking_along_x(), K, noise=noise, rng=np.random.default_rng(2))
    edges, _ = depth_edges(res.depth_true, noise.edge_threshold_m)
    assert 200 < edges.sum() < 5000
    d = res.depth * 0.001
    changed = np.abs(d - res.depth_true) > 0.002
    assert not changed[~edges].any()  # interior pixels are untouched (no subpixel noise here)
    flying = edges & (d > 0.65 + 0.01) & (d < 1.2 - 0.01)  # between the box front and the wall
    dropped = edges & (res.depth == 0)
    assert flying.mean() / edges.mean() == pytest.approx(noise.flying_pixel_prob, abs=0.1)
    assert dropped.mean() / edges.mean() == pytest.approx(noise.edge_dropout_prob, abs=0.1)


def test_same_seed_same_frame_different_seed_different(tmp_path):
    scene = wall_scene(tmp_path, 0.9)
    T = camera_looking_along_x()
    a = render(scene, T, K, noise=D435Noise(), rng=np.random.default_rng(11))
    b = render(scene, T, K, noise=D435Noise(), rng=np.random.default_rng(11))
    c = render(scene, T, K, noise=D435Noise(), rng=np.random.default_rng(12))
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.color, b.color)
    assert not np.array_equal(a.depth, c.depth)
    assert not np.array_equal(a.color, c.color)


def test_texture_colours_land_where_they_should(tmp_path):
    """A cube whose faces carry a 4-colour texture: each quadrant of the face seen by the camera shows
    its colour at the pixels it projects to (exact albedo with a flat light and no noise)."""
    obj = load_object(str(write_textured_box_obj(tmp_path, size=0.1)))
    T_obj = make_transform(translation=[0.5, 0.0, -0.05])  # -x face at x = 0.45, z in [-0.05, 0.05]
    scene = RenderScene(obj, T_obj, table=None, lighting=FLAT_LIGHT)
    T_cam = camera_looking_along_x()
    res = render(scene, T_cam, K, noise=None)
    expected = {(+0.025, +0.025): TOP_LEFT, (-0.025, +0.025): TOP_RIGHT,  # (y, z) on the face: right = -y
                (+0.025, -0.025): BOTTOM_LEFT, (-0.025, -0.025): BOTTOM_RIGHT}
    for (y, z), rgb in expected.items():
        u, v = project(T_cam, np.array([0.45, y, z]))
        patch = res.color[v - 3:v + 4, u - 3:u + 4].reshape(-1, 3)
        assert np.all(patch == rgb), ((y, z), patch[0])
        assert res.labels[v, u] == LABEL_OBJECT
        assert res.depth_true[v, u] == pytest.approx(0.45, abs=1e-5)
    # the same face seen tilted from the side still maps the same colours onto the same surface points
    T_side = make_transform(rot_z(0.3) @ R_LOOK_X, [0.1, -0.15, 0.0])
    res2 = render(scene, T_side, K, noise=None)
    for (y, z), rgb in expected.items():
        u, v = project(T_side, np.array([0.45, y, z]))
        assert np.all(res2.color[v - 1:v + 2, u - 1:u + 2].reshape(-1, 3) == rgb)


def test_shading_darkens_faces_turned_from_the_light(tmp_path):
    obj = load_object(str(write_box_ply(tmp_path, (0.1, 0.1, 0.1), rgb=(200, 200, 200))))
    light = Lighting(towards_light=(-1.0, 0.0, 0.0), ambient=0.5, diffuse=0.5)  # lights the -x face head-on
    scene = RenderScene(obj, make_transform(translation=[0.5, 0, -0.05]), table=None, lighting=light)
    res = render(scene, camera_looking_along_x(0.12), K, noise=None)  # sees the -x face and the top
    lit = res.color[res.labels == LABEL_OBJECT].astype(int).sum(axis=1)
    assert lit.max() == pytest.approx(3 * 200, abs=3)  # n . l = 1 on the front face
    assert lit.min() == pytest.approx(3 * 100, abs=3)  # top face: ambient only


def test_table_is_the_plane_z0_with_labels(tmp_path):
    shared = load_object(str(write_box_ply(tmp_path, (0.06, 0.06, 0.12))))
    scene = RenderScene(shared, make_transform(translation=[0.4, 0.0, 0.0]), table=TableSpec())
    T = make_transform(R_LOOK_X @ rot_x(-0.6), [0.0, 0.0, 0.3])  # pitched down 34 degrees
    res = render(scene, T, K, noise=None)
    table = res.labels == LABEL_TABLE
    assert table.sum() > 50000 and (res.labels == LABEL_OBJECT).sum() > 1000
    # back-project table pixels: they lie on z = 0
    v, u = np.nonzero(table)
    z = res.depth_true[v, u]
    p_cam = np.stack([(u - K.cx) / K.fx * z, (v - K.cy) / K.fy * z, z], axis=1)
    p_base = p_cam @ T[:3, :3].T + T[:3, 3]
    assert np.abs(p_base[:, 2]).max() < 1e-4
    # the table has texture (something for colour ICP) but is mild
    tcol = res.color[table].astype(float)
    assert 3.0 < tcol.std(axis=0).mean() < 40.0
    assert (res.labels == LABEL_NONE).sum() + table.sum() + (res.labels == LABEL_OBJECT).sum() == 640 * 480


def test_hope_object_renders_textured(tmp_path):
    from tests.conftest import shared_data

    shared_data("hope", "milk")
    obj = load_object("milk")
    scene = RenderScene(obj, make_transform(translation=[0.4, 0, 0]))
    T = make_transform(R_LOOK_X, [0.0, 0.0, 0.095])
    res = render(scene, T, K, noise=D435Noise(), rng=np.random.default_rng(0))
    obj_px = res.labels == LABEL_OBJECT
    # the carton is 7.3 cm wide and 19 cm tall at ~0.36 m: roughly 125 x 320 px
    cols = np.nonzero(obj_px.any(axis=0))[0]
    rows = np.nonzero(obj_px.any(axis=1))[0]
    assert np.ptp(cols) == pytest.approx(615 * 0.073 / 0.365, rel=0.1)
    assert np.ptp(rows) == pytest.approx(615 * 0.19 / 0.37, rel=0.1)
    # textured: many distinct colours on the object, and depth of the front face about 0.36 m
    assert len(np.unique(res.color[obj_px].reshape(-1, 3) // 16, axis=0)) > 20
    front = res.depth[obj_px & (res.depth > 0)] * 0.001
    assert np.median(front) == pytest.approx(0.4 - 0.036, abs=0.01)


def test_bad_inputs_are_typed_errors(tmp_path):
    scene = wall_scene(tmp_path, 1.0)
    with pytest.raises(SimInputError):
        render(scene, np.full((4, 4), np.nan), K, noise=None)
    with pytest.raises(SimInputError):
        render(scene, np.eye(3), K, noise=None)
    with pytest.raises(SimInputError):
        render(scene, np.diag([2.0, 1, 1, 1]), K, noise=None)
    with pytest.raises(SimInputError):
        render(scene, np.eye(4), K, noise=D435Noise(), rng=None)
    with pytest.raises(SimInputError):
        D435Noise(dropout_prob=1.5)


@pytest.mark.parametrize("height,pitch", [(0.3, -0.6), (0.05, -0.1), (0.6, -1.2)])
def test_analytic_table_rays_match_full_ray_casting(tmp_path, height, pitch):
    """Rays that only meet the table top are intersected analytically: the frame must be identical to
    casting every ray (object in view, table edge in view, camera close above the table)."""
    obj = load_object(str(write_textured_box_obj(tmp_path, size=0.08)))
    scene = RenderScene(obj, make_transform(rot_z(0.4), [0.45, 0.05, 0.0]), table=TableSpec())
    T = make_transform(rot_z(0.1) @ R_LOOK_X @ rot_x(pitch), [0.0, 0.0, height])
    fast = render(scene, T, K, noise=D435Noise(), rng=np.random.default_rng(3))
    full = render(scene, T, K, noise=D435Noise(), rng=np.random.default_rng(3), full_cast=True)
    assert (fast.labels == LABEL_OBJECT).sum() > 500
    np.testing.assert_array_equal(fast.labels, full.labels)
    np.testing.assert_allclose(fast.depth_true, full.depth_true, atol=2e-6)
    assert np.mean(fast.depth != full.depth) < 1e-3  # rounding at exact mm boundaries only
    assert np.mean(np.any(fast.color != full.color, axis=-1)) < 1e-3
