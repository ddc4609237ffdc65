"""The object catalogue: HOPE names, user meshes in every format, the object frame, clear errors."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from services.sim.catalogue import load_object, up_axis_rotation
from services.sim.errors import SimObjectError
from tests.conftest import shared_data
from tests.sim.meshes import (
    BOTTOM_LEFT,
    TOP_LEFT,
    write_box_ply,
    write_textured_box_glb,
    write_textured_box_obj,
)

HOPE_SIZES_M = {  # real sizes (x, y, z up) after scale 0.01 and y-up -> z-up
    "milk": (0.072, 0.073, 0.190),
    "alphabet_soup": (0.066, 0.071, 0.084),
}


@pytest.mark.parametrize("name", sorted(HOPE_SIZES_M))
def test_hope_object_in_metres_z_up_footprint_at_origin(name):
    shared_data("hope", name)
    obj = load_object(name)
    assert obj.name == name and obj.appearance == "texture"
    np.testing.assert_allclose(obj.extent, HOPE_SIZES_M[name], atol=0.002)
    lo, hi = obj.vertices.min(axis=0), obj.vertices.max(axis=0)
    assert lo[2] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose((lo[:2] + hi[:2]) / 2, 0.0, atol=1e-9)
    # the legacy mesh carries the same geometry and texture as the arrays
    np.testing.assert_allclose(np.asarray(obj.mesh.vertices), obj.vertices)
    assert len(obj.mesh.textures) == 1 and obj.mesh.has_triangle_uvs()


def test_milk_carton_gable_is_on_top():
    """The carton's gable (narrow ridge) must end up at the top: y is HOPE's up axis, not -y."""
    shared_data("hope", "milk")
    obj = load_object("milk")
    v = obj.vertices
    top = v[v[:, 2] > obj.height - 0.005]
    bottom = v[v[:, 2] < 0.005]
    assert min(np.ptp(top[:, 0]), np.ptp(top[:, 1])) < 0.01  # ridge
    assert min(np.ptp(bottom[:, 0]), np.ptp(bottom[:, 1])) > 0.06  # full base


def test_cache_returns_independent_meshes():
    shared_data("hope", "milk")
    a = load_object("milk")
    a.mesh.translate((1.0, 2.0, 3.0))
    b = load_object("milk")
    assert np.asarray(b.mesh.vertices)[:, 2].min() == pytest.approx(0.0, abs=1e-9)
    assert b.vertices is a.vertices  # parsed once
    with pytest.raises(ValueError):
        b.vertices[0, 0] = 1.0  # shared arrays are read-only


@pytest.mark.parametrize("up", ["x", "-x", "y", "-y", "z", "-z", "+y"])
def test_up_axis_rotation_maps_axis_to_z(up):
    axis = np.zeros(3)
    axis["xyz".index(up[-1])] = -1.0 if up.startswith("-") else 1.0
    R = up_axis_rotation(up)
    np.testing.assert_allclose(R @ axis, [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_user_mesh_scale_and_up_axis(tmp_path):
    path = write_box_ply(tmp_path, (10.0, 20.0, 30.0), rgb=(10, 200, 30))  # in cm, y is "up"
    obj = load_object(str(path), scale=0.01, up_axis="y")
    np.testing.assert_allclose(obj.extent, [0.10, 0.30, 0.20], atol=1e-9)  # y (20 cm) is now z
    assert obj.appearance == "vertex_colors"
    pts, cols = obj.gt_colored_points(200)
    assert np.all(np.abs(cols.astype(int) - [10, 200, 30]) <= 1)


def test_textured_obj_and_glb_sample_the_same_texture(tmp_path):
    """A known UV layout: the -x face's top-left quarter is TOP_LEFT, bottom-left is BOTTOM_LEFT, in both
    formats (Open3D stores textures flipped; the catalogue must undo that for both)."""
    for path in (write_textured_box_obj(tmp_path / "obj"), write_textured_box_glb(tmp_path / "glb")):
        obj = load_object(str(path))
        assert obj.appearance == "texture", path
        # triangles of the -x face: all vertices at x = min
        v = obj.vertices[obj.triangles]
        face = np.flatnonzero(np.all(np.abs(v[:, :, 0] - v[:, :, 0].min()) < 1e-9, axis=1))
        assert len(face) == 2
        # sample points on that face and compare with where they are on it (seen from -x: right = -y)
        pts, tri, bary = obj.sample_surface(20000, seed=3)
        on = np.isin(tri, face)
        p, c = pts[on], obj.surface_colors(tri[on], bary[on])
        s = obj.extent[1]
        right = (s / 2 - p[:, 1]) / s  # 0 at the left edge, 1 at the right edge
        up = p[:, 2] / obj.extent[2]
        inner = (np.abs(right - 0.5) > 0.05) & (np.abs(up - 0.5) > 0.05)  # away from quadrant borders
        tl = inner & (right < 0.5) & (up > 0.5)
        bl = inner & (right < 0.5) & (up < 0.5)
        assert tl.sum() > 100 and bl.sum() > 100
        np.testing.assert_array_equal(c[tl], np.broadcast_to(TOP_LEFT, c[tl].shape), err_msg=str(path))
        np.testing.assert_array_equal(c[bl], np.broadcast_to(BOTTOM_LEFT, c[bl].shape), err_msg=str(path))


def test_stl_without_colours_is_untextured(tmp_path):
    box = o3d.geometry.TriangleMesh.create_box(0.05, 0.05, 0.05)
    box.compute_triangle_normals()
    path = tmp_path / "b.stl"
    o3d.io.write_triangle_mesh(str(path), box)
    obj = load_object(str(path))
    assert obj.appearance == "untextured"
    assert obj.gt_colored_points(10)[1].shape == (10, 3)


def test_gt_points_lie_on_the_surface_uniformly(tmp_path):
    path = write_box_ply(tmp_path, (0.1, 0.2, 0.3))
    obj = load_object(str(path))
    pts = obj.gt_points(30000, seed=5)
    half = np.array([0.05, 0.1])
    # every sample is on one of the faces
    on_face = (np.isclose(np.abs(pts[:, 0]), half[0], atol=1e-9) | np.isclose(np.abs(pts[:, 1]), half[1], atol=1e-9)
               | np.isclose(pts[:, 2], 0.0, atol=1e-9) | np.isclose(pts[:, 2], 0.3, atol=1e-9))
    assert on_face.all()
    # and faces get samples in proportion to their area (0.2*0.3 of 0.22 total for each +-x face)
    frac_x = np.mean(np.isclose(pts[:, 0], 0.05, atol=1e-9))
    assert frac_x == pytest.approx(0.06 / 0.22, abs=0.01)
    np.testing.assert_array_equal(pts, obj.gt_points(30000, seed=5))  # deterministic


def test_unknown_name_lists_known_objects():
    with pytest.raises(SimObjectError) as err:
        load_object("no_such_object_xyz")
    assert err.value.code == "object_not_found"
    assert "no_such_object_xyz" in err.value.message


def test_missing_file(tmp_path):
    with pytest.raises(SimObjectError) as err:
        load_object(str(tmp_path / "absent.obj"))
    assert err.value.code == "object_not_found"


@pytest.mark.parametrize("suffix,content", [
    (".obj", b"this is not an obj\x00\x01\x02 f 1 2 3\n"),
    (".ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n"),
    (".stl", b"\x00" * 10),
])
def test_corrupt_mesh_is_a_typed_error(tmp_path, suffix, content):
    path = tmp_path / f"broken{suffix}"
    path.write_bytes(content)
    with pytest.raises(SimObjectError) as err:
        load_object(str(path))
    assert err.value.code == "bad_mesh"
    assert "broken" in err.value.message


def test_nan_vertices_and_flat_meshes_are_rejected(tmp_path):
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n")
    with pytest.raises(SimObjectError, match="NaN"):
        load_object(str(tmp_path / "nan.obj"))
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(SimObjectError, match="flat"):
        load_object(str(tmp_path / "flat.obj"))


def test_bad_arguments(tmp_path):
    path = write_box_ply(tmp_path, (0.1, 0.1, 0.1))
    with pytest.raises(SimObjectError) as err:
        load_object(str(path), scale=-1.0)
    assert err.value.code == "bad_argument"
    with pytest.raises(SimObjectError) as err:
        load_object(str(path), up_axis="w")
    assert err.value.code == "bad_argument"
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(SimObjectError):
        load_object(str(tmp_path / "notes.txt"))


def test_materials_without_texture_keep_their_triangles_untextured(tmp_path):
    """Two materials, only the second textured: Open3D keeps an empty slot for the first, and the
    material ids must still pick the right one (the first triangle is grey, the second textured)."""
    from PIL import Image

    from common.messages import d435_intrinsics
    from services.sim.catalogue import DEFAULT_COLOR
    from services.sim.render import Lighting, RenderScene, render

    Image.fromarray(np.full((8, 8, 3), (10, 120, 250), np.uint8)).save(tmp_path / "blue.png")
    (tmp_path / "two.mtl").write_text("newmtl plain\nKd 1 0 0\nnewmtl tex\nmap_Kd blue.png\n")
    (tmp_path / "two.obj").write_text(
        "mtllib two.mtl\nv 0 0 0\nv 0.1 0 0\nv 0.1 0.1 0\nv 0 0.1 0.05\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl plain\nf 1/1 2/2 3/3\nusemtl tex\nf 1/1 3/3 4/4\n")
    obj = load_object(str(tmp_path / "two.obj"))
    assert obj.appearance == "texture"
    np.testing.assert_array_equal(obj.surface_colors(np.array([0, 1]), np.full((2, 2), 0.3)),
                                  [DEFAULT_COLOR, (10, 120, 250)])
    # the renderer takes the multi-material path and agrees
    from common.geometry import make_transform

    scene = RenderScene(obj, make_transform(translation=[0, 0, 0]), table=None,
                        lighting=Lighting(ambient=1.0, diffuse=0.0))
    T = make_transform(np.diag([1.0, -1.0, -1.0]), [0.0, 0.0, 0.5])  # looking straight down
    res = render(scene, T, d435_intrinsics(320, 240), noise=None)
    seen = {tuple(c) for c in res.color[res.labels == 2].reshape(-1, 3)}
    assert tuple(DEFAULT_COLOR) in seen and (10, 120, 250) in seen
