"""The sim backend: the pose goes through to the twin, and what the twin returns is validated."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from common.errors import ServiceUnavailable
from common.geometry import look_at
from common.messages import RGBDFrame
from services.camera import make_camera
from services.camera.errors import BadFrameError, BadPoseError, CameraConfigError, CameraError, CaptureTimeout
from services.camera.intrinsics import d435_color_intrinsics
from services.camera.sim import SimCamera, SimCameraConfig

WALL_Z = 0.8
TRUE_OFFSET = np.array([0.002, -0.001, 0.0])  # the twin's true camera sits 2 mm off the belief


class FakeTwin:
    """Stands in for the sim service's render: a wall WALL_Z in front of the camera, D435 intrinsics."""

    def __init__(self, belief: np.ndarray | None = None, **overrides):
        self.calls: list[tuple[np.ndarray | None, int, int]] = []
        self.belief = look_at([0.2, 0.0, 0.5], [0.36, 0.0, 0.0]) if belief is None else belief
        self.overrides = overrides

    def __call__(self, T, width, height) -> RGBDFrame:
        self.calls.append((None if T is None else np.array(T), width, height))
        intr = d435_color_intrinsics(width, height)
        T_believed = self.belief if T is None else T
        truth = T_believed.copy()
        truth[:3, 3] += TRUE_OFFSET
        fields = dict(color=np.full((height, width, 3), 200, np.uint8),
                      depth=np.full((height, width), int(WALL_Z / 0.001), np.uint16), depth_scale=0.001,
                      intrinsics=intr, T_base_camera=T_believed, T_base_camera_true=truth,
                      meta={"renderer": "fake"})
        fields.update(self.overrides)
        return RGBDFrame(**fields)


POSE = look_at([0.25, 0.1, 0.45], [0.36, 0.0, 0.05])


def test_pose_is_passed_through_and_stamped():
    twin = FakeTwin()
    with SimCamera(SimCameraConfig(), render_request=twin) as cam:
        a = cam.capture(POSE)
        b = cam.capture(POSE)
    T_sent, w, h = twin.calls[0]
    np.testing.assert_array_equal(T_sent, POSE)
    assert (w, h) == (640, 480)
    np.testing.assert_array_equal(a.T_base_camera, POSE)
    np.testing.assert_allclose(a.T_base_camera_true[:3, 3], POSE[:3, 3] + TRUE_OFFSET)
    assert a.meta["pose_source"] == "given" and a.meta["renderer"] == "fake"
    assert (a.seq, b.seq) == (0, 1)
    assert a.intrinsics == d435_color_intrinsics(640, 480)
    assert a.depth[240, 320] * a.depth_scale == pytest.approx(WALL_Z)


def test_without_a_pose_the_twins_belief_is_kept():
    twin = FakeTwin()
    with SimCamera(render_request=twin) as cam:
        f = cam.capture()
    assert twin.calls[0][0] is None
    np.testing.assert_array_equal(f.T_base_camera, twin.belief)
    assert f.meta["pose_source"] == "sim"


def test_wide_mode_asks_for_848x480():
    twin = FakeTwin()
    with make_camera({"backend": "sim", "width": 848, "height": 480}, render_request=twin) as cam:
        f = cam.capture(POSE)
    assert twin.calls[0][1:] == (848, 480)
    assert f.intrinsics.cx == 424.0 and f.color.shape == (480, 848, 3)


def test_async_render_request():
    twin = FakeTwin()

    async def render(T, w, h):
        await asyncio.sleep(0.01)
        return twin(T, w, h)

    async def main():
        cam = SimCamera(render_request=render)
        await cam.aconnect()
        f = await cam.acapture(POSE)
        with pytest.raises(CameraError) as err:  # the sync face cannot block a running loop
            cam.capture(POSE)
        assert err.value.code == "use_acapture"
        return f

    f = asyncio.run(main())
    np.testing.assert_array_equal(f.T_base_camera, POSE)
    # outside any loop the sync face drives the coroutine itself
    with SimCamera(render_request=render) as cam:
        assert cam.capture(POSE).seq == 0


def test_sync_render_request_through_acapture():
    twin = FakeTwin()

    async def main():
        with SimCamera(render_request=twin) as cam:
            return await cam.acapture(POSE)

    assert asyncio.run(main()).meta["pose_source"] == "given"


def test_silent_twin_times_out():
    async def never(T, w, h):
        await asyncio.sleep(10)

    async def main():
        with SimCamera(SimCameraConfig(timeout_s=0.05), render_request=never) as cam:
            await cam.acapture(POSE)

    with pytest.raises(CaptureTimeout) as err:
        asyncio.run(main())
    assert err.value.code == "timeout"


def test_twin_errors_keep_their_code():
    def down(T, w, h):
        raise ServiceUnavailable("no sim service answered")

    with SimCamera(render_request=down) as cam, pytest.raises(ServiceUnavailable) as err:
        cam.capture(POSE)
    assert err.value.code == "unavailable"


@pytest.mark.parametrize("override,reason", [
    ({"color": np.zeros((480, 640, 3), np.float32)}, "color must be a uint8"),
    ({"color": np.zeros((480, 640), np.uint8)}, "color must be a uint8"),
    ({"depth": np.zeros((480, 640), np.float32)}, "depth must be a uint16"),
    ({"depth": np.zeros((240, 320), np.uint16)}, "sizes differ"),
    ({"depth_scale": -1.0}, "depth_scale"),
])
def test_malformed_frames_from_the_twin_are_rejected(override, reason):
    with SimCamera(render_request=FakeTwin(**override)) as cam, pytest.raises(BadFrameError) as err:
        cam.capture(POSE)
    assert err.value.code == "bad_frame" and reason in err.value.message


def test_wrong_size_and_wrong_type_are_rejected():
    def small(T, w, h):
        return FakeTwin()(T, 640, 480)

    with SimCamera(SimCameraConfig(width=848), render_request=small) as cam, pytest.raises(BadFrameError) as err:
        cam.capture(POSE)
    assert "requested size" in err.value.message

    with SimCamera(render_request=lambda T, w, h: {"color": None}) as cam, pytest.raises(BadFrameError):
        cam.capture(POSE)

    nan_pose = np.full((4, 4), np.nan)
    with SimCamera(render_request=FakeTwin(belief=nan_pose)) as cam, pytest.raises(BadFrameError):
        cam.capture(None)


@pytest.mark.parametrize("bad", [np.eye(3), np.full((4, 4), np.nan), np.diag([1.0, 1.0, -1.0, 1.0]),
                                 np.diag([2.0, 1.0, 1.0, 1.0]), "pose"])
def test_bad_pose_is_rejected_before_the_twin_is_asked(bad):
    twin = FakeTwin()
    with SimCamera(render_request=twin) as cam, pytest.raises(BadPoseError) as err:
        cam.capture(bad)
    assert err.value.code == "bad_pose" and twin.calls == []


def test_config_and_construction_errors():
    with pytest.raises(CameraConfigError):
        SimCameraConfig(width=1280, height=720)  # no D435 color preset for it
    with pytest.raises(CameraConfigError):
        make_camera({"backend": "sim"})  # no render_request
    with pytest.raises(CameraConfigError):
        SimCamera().connect()


def test_concurrent_async_captures_are_serialised():
    twin = FakeTwin()
    active = []

    async def render(T, w, h):
        active.append(1)
        assert len(active) == 1, "two renders ran at once"
        await asyncio.sleep(0.01)
        active.pop()
        return twin(T, w, h)

    async def main():
        with SimCamera(render_request=render) as cam:
            return await asyncio.gather(*(cam.acapture(POSE) for _ in range(4)))

    assert sorted(f.seq for f in asyncio.run(main())) == [0, 1, 2, 3]
