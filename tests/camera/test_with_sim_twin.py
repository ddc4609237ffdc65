"""The camera backends against the real digital twin (services/sim), where it is importable.

Guards the seams between the two parts: the twin renders with the camera's D435 presets, its frames pass
the camera's checks, and a session the twin writes replays frame for frame.
"""

from __future__ import annotations

import numpy as np
import pytest

from services.camera.intrinsics import d435_color_intrinsics
from services.camera.replay import ReplayCamera, ReplayCameraConfig
from services.camera.sim import SimCamera, SimCameraConfig

sensor_model = pytest.importorskip("services.sim.sensor_model")
scenario = pytest.importorskip("bench.scenario")
world_mod = pytest.importorskip("services.sim.world")

pytestmark = pytest.mark.timeout(180)


def test_sim_camera_on_the_twin():
    obj_xy = np.array([0.36, 0.0])
    world = world_mod.World("milk", profile="ideal", seed=3, object_pose=world_mod.default_object_pose(*obj_xy))
    T_true = scenario.camera_look_at(np.array([0.0, 0.0, 0.35]), np.array([*obj_xy, 0.1]))

    def render(T, width, height):
        return world.render_frame(T_true, d435_color_intrinsics(width, height))

    with SimCamera(SimCameraConfig(width=640, height=480), render_request=render) as cam:
        f = cam.capture()
    assert f.meta["pose_source"] == "sim" and f.intrinsics == d435_color_intrinsics(640, 480)
    np.testing.assert_allclose(f.T_base_camera_true, T_true)
    z = f.depth[200:280, 280:360] * f.depth_scale  # the carton fills the image centre
    z = z[z > 0]
    dist = np.linalg.norm(np.array([0.36, 0.0, 0.1]) - T_true[:3, 3])
    assert z.size > 1000 and 0.1 < np.median(z) < dist


def test_a_session_written_by_the_twin_replays_frame_for_frame(tmp_path):
    views = scenario.simulated_views("milk", views=2, scans_per_view=2, seed=5)
    scenario.write_session(tmp_path, views)
    originals = [f for frames in views for f in frames]
    with ReplayCamera(ReplayCameraConfig(session_dir=tmp_path)) as cam:
        for orig in originals:
            f = cam.capture()
            np.testing.assert_array_equal(f.color, orig.color)
            np.testing.assert_array_equal(f.depth, orig.depth)
            np.testing.assert_allclose(f.T_base_camera, orig.T_base_camera)
            np.testing.assert_allclose(f.T_base_camera_true, orig.T_base_camera_true)
            assert f.intrinsics == orig.intrinsics and f.seq == orig.seq
            assert f.meta["commanded_turn_deg"] == orig.meta["commanded_turn_deg"]
