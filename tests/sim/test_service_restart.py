"""The sim service as a process, killed and restarted: it comes back with the world it had (from its state
file), renders the frame the unkilled twin would have rendered next, bit for bit, and a clean stop
removes the file so the next start is fresh."""

from __future__ import annotations

import time

import numpy as np
import pytest

from bench.scenario import camera_look_at
from common import keys
from common.api import CaptureRequest
from common.client import live_services, request_sync
from common.geometry import make_transform
from common.launcher import ProcessSpec
from common.messages import Health, JointState, Ok, Request, RGBDFrame, d435_intrinsics
from services.sim.world import World
from tests.sim.meshes import write_box_ply

pytestmark = pytest.mark.timeout(240)
ROBOT = keys.DEFAULT_ROBOT
NAMES = [f"robot1/joint{i}" for i in range(1, 7)]
Q = np.linspace(-0.3, 0.3, 6)


def _ask(group, op: str, msg=None, timeout: float = 30.0):  # noqa: ANN001, ANN202
    return request_sync(group.session, keys.sim(ROBOT, op), msg, timeout=timeout)


def _health(group) -> Health:  # noqa: ANN001
    inst = next(i for s, i in live_services(group.session, timeout=1.0) if s == "sim")
    return request_sync(group.session, keys.health("sim", inst), timeout=10.0)


def _wait_gone(group) -> None:  # noqa: ANN001
    deadline = time.monotonic() + 30
    while any(s == "sim" for s, _ in live_services(group.session, timeout=0.5)):
        assert time.monotonic() < deadline, "the killed twin's token did not go away"
        time.sleep(0.2)


def test_a_killed_twin_comes_back_with_its_world_and_a_clean_stop_starts_fresh(service_group, tmp_path):
    mesh = write_box_ply(tmp_path, (0.06, 0.06, 0.15), name="carton")
    state = tmp_path / "state" / "sim.json"
    spec = ProcessSpec("services.sim", ["--object", str(mesh), "--profile", "robot-turned", "--seed", "3",
                                        "--state-file", str(state)], service="sim")
    group = service_group
    group.launch([spec], timeout=120)
    assert state.is_file() and not _health(group).info["restored"]

    cam = camera_look_at(np.array([0.2, 0.1, 0.35]), np.array([0.5, 0.0, 0.07]))
    G = make_transform(np.eye(3), [0.3, 0.3, 0.3])  # the gripper well away from the carton
    assert isinstance(_ask(group, "joints", JointState(names=NAMES, position=Q, T_base_camera=cam,
                                                      T_base_gripper=G)), Ok)
    achieved = _ask(group, "world", Request(params={"op": "turn", "angle_deg": 30.0})).info["achieved_turn_deg"]
    _ask(group, "render", CaptureRequest(width=640, height=480))
    before = _ask(group, "world", Request(params={"op": "state"})).info

    group.kill("sim")  # SIGKILL: no clean shutdown, the file stays
    _wait_gone(group)
    assert state.is_file()
    group.start(spec)
    group.wait_alive(["sim"], timeout=120)
    assert _health(group).info["restored"]
    after = _ask(group, "world", Request(params={"op": "state"})).info
    for k in ("object", "profile", "seed", "attached", "gripper_opening", "joint_names", "counts"):
        assert after[k] == before[k], k
    np.testing.assert_array_equal(after["joint_positions"], before["joint_positions"])
    for k in ("T_base_object", "T_base_camera", "hand_eye_error", "last_set_down"):
        np.testing.assert_array_equal(np.asarray(after["ground_truth"][k], dtype=object),
                                      np.asarray(before["ground_truth"][k], dtype=object))
    frame = _ask(group, "render", CaptureRequest(width=640, height=480))  # no joints re-sent: pose from the file
    assert isinstance(frame, RGBDFrame) and frame.seq == 2

    # the same story without a kill, in this process: the restarted twin rendered exactly its frame 2
    ref = World(str(mesh), profile="robot-turned", seed=3)
    ref.set_joint_state(NAMES, Q, T_base_camera=cam, T_base_gripper=G)
    assert ref.turn_object(30.0) == achieved
    ref.render_frame(None, d435_intrinsics(640, 480), 1)
    expected = ref.render_frame(None, d435_intrinsics(640, 480), 2)
    np.testing.assert_array_equal(frame.depth, expected.depth)
    np.testing.assert_array_equal(frame.color, expected.color)
    np.testing.assert_array_equal(frame.T_base_camera, expected.T_base_camera)

    assert group.stop("sim") == 0  # SIGTERM: a clean stop ends the world
    assert not state.exists()
