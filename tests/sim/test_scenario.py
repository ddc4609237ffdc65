"""The scenario helper: deterministic views with commanded turns and ground truth, written as a session
folder, and frames whose depth lands on the true object surface."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image
from scipy.spatial import cKDTree

from bench.scenario import ScanPoses, camera_look_at, simulated_views, write_session
from common.geometry import yaw_deg_about
from common.messages import d435_intrinsics
from common.session_folder import read_scan, read_session
from services.sim.catalogue import load_object
from services.sim.ground_truth import posed_surface, recorded_pose, true_object_points
from services.sim.render import LABEL_OBJECT
from tests.sim.meshes import write_textured_box_obj

SMALL = d435_intrinsics(320, 240)


@pytest.fixture(scope="module")
def cube(tmp_path_factory):
    return str(write_textured_box_obj(tmp_path_factory.mktemp("cube"), size=0.08))


def test_views_scans_turns_and_determinism(cube):
    views = simulated_views(cube, views=3, scans_per_view=2, profile="hand-turned", seed=4, intrinsics=SMALL)
    again = simulated_views(cube, views=3, scans_per_view=2, profile="hand-turned", seed=4, intrinsics=SMALL)
    other = simulated_views(cube, views=3, scans_per_view=2, profile="hand-turned", seed=5, intrinsics=SMALL)
    assert [len(v) for v in views] == [2, 2, 2]
    for k, frames in enumerate(views):
        for j, f in enumerate(frames):
            assert (f.meta["view"], f.meta["scan"]) == (k, j)
            assert f.meta["commanded_turn_deg"] == 30.0 * k
            assert f.color.shape == (240, 320, 3) and f.depth.shape == (240, 320)
            g = again[k][j]
            np.testing.assert_array_equal(f.color, g.color)
            np.testing.assert_array_equal(f.depth, g.depth)
            np.testing.assert_array_equal(f.T_base_camera, g.T_base_camera)
    assert not np.array_equal(views[2][0].depth, other[2][0].depth)
    # the recorded true object pose turns by the recorded achieved turn, within hand-turned's 30 +- 5
    T0 = np.asarray(views[0][0].meta["T_base_object_true"])
    for k in (1, 2):
        Tk = np.asarray(views[k][0].meta["T_base_object_true"])
        turn = yaw_deg_about([0, 0, 1], Tk[:3, :3] @ T0[:3, :3].T)
        assert turn == pytest.approx(views[k][0].meta["achieved_turn_deg_true"], abs=1e-6)
        assert abs(turn - 30.0 * k) <= 5.0 * k


def test_depth_lands_on_the_true_surface(cube):
    """Back-project the object pixels of every frame with the true camera pose: they lie on the true mesh
    (ideal profile: only 1 mm quantisation)."""
    views = simulated_views(cube, views=2, scans_per_view=3, profile="ideal", seed=0, intrinsics=SMALL)
    for frames in views:
        for f in frames:
            tree = cKDTree(true_object_points(f, 60000))
            v, u = np.nonzero(f.depth > 0)
            z = f.depth[v, u] * f.depth_scale
            K = f.intrinsics
            pts = np.stack([(u - K.cx) / K.fx * z, (v - K.cy) / K.fy * z, z], axis=1)
            pts = pts @ f.T_base_camera_true[:3, :3].T + f.T_base_camera_true[:3, 3]
            near_obj = pts[:, 2] > 0.003  # above the table
            assert near_obj.sum() > 500
            d, _ = tree.query(pts[near_obj])
            assert np.median(d) < 0.0015 and np.percentile(d, 95) < 0.003


def test_scan_poses_look_at_the_object_from_its_front(cube):
    center = np.array([0.36, 0.0, 0.04])
    poses = ScanPoses().poses(center, 3)
    for T in poses:
        to_center = center - T[:3, 3]
        assert 0.35 <= np.linalg.norm(to_center) <= 0.45
        np.testing.assert_allclose(T[:3, 2], to_center / np.linalg.norm(to_center), atol=1e-9)
        assert T[2, 1] < 0  # image upright: the camera's y (down in the image) points down
        elevation = np.degrees(np.arcsin(-T[2, 2]))
        assert 30.0 <= elevation <= 50.0
        assert T[0, 3] < center[0]  # between the robot base and the object
    az = [np.degrees(np.arctan2(T[1, 3], T[0, 3] - center[0])) % 360 for T in poses]
    assert max(az) - min(az) == pytest.approx(50.0, abs=1e-6)
    np.testing.assert_allclose(camera_look_at([0, 0, 0.5], [0.3, 0, 0])[:3, 2], np.array([0.3, 0, -0.5]) /
                               np.linalg.norm([0.3, 0, -0.5]))


def test_object_shows_in_every_frame(cube):
    from services.sim.render import RenderScene, render

    views = simulated_views(cube, views=1, scans_per_view=3, intrinsics=SMALL)
    obj = load_object(cube)
    for f in views[0]:
        scene = RenderScene(obj, np.asarray(f.meta["T_base_object_true"]))
        labels = render(scene, f.T_base_camera_true, SMALL, noise=None).labels
        ys, xs = np.nonzero(labels == LABEL_OBJECT)
        assert len(xs) > 1000
        assert abs(xs.mean() - SMALL.cx) < 40 and abs(ys.mean() - SMALL.cy) < 40  # roughly centred


def test_write_session(tmp_path, cube):
    views = simulated_views(cube, views=2, scans_per_view=2, profile="robot-turned", seed=1, intrinsics=SMALL)
    path = write_session(tmp_path / "s", views, extra={"note": "test"})
    info = read_session(path)
    assert [v["index"] for v in info.views] == [0, 1]
    assert info.commanded_turn_deg(1) == 30.0
    data = json.loads((path / "session.json").read_text())
    assert data["profile"] == "robot-turned" and data["seed"] == 1 and data["note"] == "test"
    assert data["object"] == "qbox" and data["source"] == "sim"
    model = data["ground_truth"]["object_model"]
    again = load_object(model["source"], scale=model["scale"], up_axis=model["up_axis"])
    np.testing.assert_allclose(again.vertices, load_object(cube).vertices)
    np.testing.assert_allclose(data["views"][1]["ground_truth"]["T_base_object"],
                               views[1][0].meta["T_base_object_true"])
    for k in range(2):
        assert info.scans(k) == [0, 1]
        d = path / f"view_{k:02d}" / "scan_1"
        meta = json.loads((d / "meta.json").read_text())
        f = views[k][1]
        np.testing.assert_allclose(meta["T_base_camera"], f.T_base_camera)
        np.testing.assert_allclose(meta["ground_truth"]["T_base_camera"], f.T_base_camera_true)
        assert meta["commanded_turn_deg"] == 30.0 * k and meta["intrinsics"]["width"] == 320
        np.testing.assert_array_equal(np.asarray(Image.open(d / "depth.png")), f.depth)
        np.testing.assert_array_equal(np.asarray(Image.open(d / "color.png").convert("RGB")), f.color)
    # read back through the common reader: same frame, and its ground truth still usable
    back = read_scan(path, 1, 0)
    np.testing.assert_array_equal(back.depth, views[1][0].depth)
    np.testing.assert_allclose(back.T_base_camera_true, views[1][0].T_base_camera_true)
    np.testing.assert_allclose(true_object_points(back, 500), true_object_points(views[1][0], 500))
    # the pose view 0 recorded places the object's true surface where the model's frame has it
    T0 = recorded_pose(path)
    np.testing.assert_allclose(T0, views[0][0].meta["T_base_object_true"])
    np.testing.assert_allclose(posed_surface(load_object(cube), T0, 500), true_object_points(views[0][0], 500))
    assert recorded_pose(tmp_path / "not-a-session") is None


@pytest.mark.slow
def test_hope_twelve_views_are_fast_enough():
    import time

    from tests.conftest import shared_data

    shared_data("hope", "milk")
    simulated_views("milk", views=1, scans_per_view=1)  # warm up (numba, caches)
    t = time.perf_counter()
    views = simulated_views("milk", views=12, scans_per_view=3, profile="robot-turned", seed=0)
    per_frame = (time.perf_counter() - t) / 36
    assert sum(len(v) for v in views) == 36
    assert per_frame < 0.2  # ~60 ms on an idle core; generous for a loaded CI machine
