"""The twin's world survives a restart: ``World.snapshot`` written by ``StateFile`` and loaded into a new
``World`` is the same world (poses, grasp, counters), renders bit-identical frames for the same camera
pose and sequence number, and makes the same random draws next; where the file lives and when it is
refused."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from bench.scenario import camera_look_at
from common.geometry import make_transform
from common.messages import d435_intrinsics
from services.sim.catalogue import load_object
from services.sim.errors import SimInputError
from services.sim.state_file import FILE_FORMAT, StateFile, network_key, resolve_state_path
from services.sim.world import DEFAULT_OBJECT_XY, SimStateError, World, default_object_pose
from tests.sim.meshes import write_box_ply

SMALL = d435_intrinsics(320, 240)
OBJ_XY = np.array(DEFAULT_OBJECT_XY)
NAMES = [f"robot1/joint{i}" for i in range(1, 7)]


@pytest.fixture
def box(tmp_path):
    return load_object(str(write_box_ply(tmp_path, (0.06, 0.06, 0.15), name="carton")))


def frontal(z: float = 0.075) -> np.ndarray:
    """Gripper approaching along base +x around the carton (x = approach, y = across the fingers)."""
    return make_transform(np.eye(3), [OBJ_XY[0], 0.0, z])


def camera() -> np.ndarray:
    return camera_look_at(np.array([0.2, 0.1, 0.35]), np.array([*OBJ_XY, 0.07]))


def restart(world: World, path) -> World:  # noqa: ANN001
    """What a killed and restarted twin does: the file is all that is left."""
    StateFile(path).save(world.snapshot(), seq=7)
    doc = StateFile(path).load()
    assert doc is not None and doc["seq"] == 7 and doc["format"] == FILE_FORMAT
    return World.from_snapshot(doc["world"])


def test_a_turned_world_restored_renders_the_same_frames_and_draws_the_same_next(box, tmp_path):
    w = World(box, profile="robot-turned", seed=4, object_pose=default_object_pose(0.5, 0.02, 15.0))
    w.turn_object(30.0)
    w.turn_object(30.0)
    w.set_joint_state(NAMES, np.linspace(-0.5, 0.5, 6), T_base_camera=camera(), T_base_gripper=frontal(0.3))
    w.render_frame(None, SMALL, 1)
    w.force_next_grasp_slip()
    r = restart(w, tmp_path / "state.json")

    assert json.dumps(r.state(), sort_keys=True) == json.dumps(w.state(), sort_keys=True)
    np.testing.assert_array_equal(r.true_object_pose(), w.true_object_pose())
    a, b = w.render_frame(None, SMALL, 2), r.render_frame(None, SMALL, 2)  # camera pose from the file
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.color, b.color)
    np.testing.assert_array_equal(a.T_base_camera, b.T_base_camera)  # same hand-eye error and jitter
    assert a.depth[a.depth > 0].size > 1000  # the scene is really in view
    # the next draws continue the same streams: the turn, and the forced slip still armed
    assert r.turn_object(30.0) == w.turn_object(30.0)
    np.testing.assert_array_equal(r.true_object_pose(), w.true_object_pose())
    G = make_transform(np.eye(3), [*r.true_object_pose()[:2, 3], 0.075])
    out_r, out_w = r.close_gripper(G, 0.0), w.close_gripper(G, 0.0)
    assert out_r == out_w and out_r.reason == "slip"


def test_a_held_object_stays_held_and_follows_the_gripper_after_a_restart(box, tmp_path):
    w = World(box, profile="robot-turned", seed=1)
    w.profile = dataclasses.replace(w.profile, slip_prob=0.0)  # this test wants the grasp (name unchanged)
    assert w.close_gripper(frontal(), 0.0).success
    w.move_gripper(frontal(0.12))
    r = World.from_snapshot(json.loads(json.dumps(w.snapshot())))
    assert r.attached and r.gripper_opening == w.gripper_opening
    np.testing.assert_array_equal(r.true_object_pose(), w.true_object_pose())
    lifted = frontal(0.2)
    r.move_gripper(lifted)
    w.move_gripper(lifted)
    np.testing.assert_array_equal(r.true_object_pose(), w.true_object_pose())
    assert r.open_gripper() == w.open_gripper()  # same set-down draw
    np.testing.assert_array_equal(r.true_object_pose(), w.true_object_pose())


def test_state_file_write_is_atomic_and_absent_file_means_fresh(box, tmp_path):
    sf = StateFile(tmp_path / "d" / "sim.json")
    assert sf.load() is None
    w = World(box)
    sf.save(w.snapshot(), seq=0)
    sf.save(w.snapshot(), seq=1)
    assert sorted(p.name for p in (tmp_path / "d").iterdir()) == ["sim.json"]  # no temporary files left
    assert sf.load()["seq"] == 1 and sf.saves == 2
    sf.discard()
    assert sf.load() is None
    sf.discard()  # twice is fine


@pytest.mark.parametrize("content", [b"{not json", b"[]", json.dumps({"format": "other/9", "world": {}}).encode(),
                                     json.dumps({"format": FILE_FORMAT, "world": {"format": 99}}).encode(),
                                     json.dumps({"format": FILE_FORMAT, "world": {"format": 1}}).encode()])
def test_an_unusable_state_file_is_a_typed_error_not_a_silent_fresh_world(tmp_path, content):
    path = tmp_path / "sim.json"
    path.write_bytes(content)
    with pytest.raises(SimStateError) as err:
        doc = StateFile(path).load()
        World.from_snapshot(doc["world"])
    assert err.value.code == "bad_snapshot"


def test_a_snapshot_with_a_broken_pose_is_refused(box):
    snap = World(box).snapshot()
    snap["T_base_object"] = (np.eye(4) * 2).tolist()
    with pytest.raises(SimInputError):
        World.from_snapshot(snap)


def test_where_the_state_file_lives(tmp_path, monkeypatch):
    monkeypatch.delenv("OBJSCAN_SIM_STATE_FILE", raising=False)
    monkeypatch.setenv("OBJSCAN_STATE_DIR", str(tmp_path))
    a = resolve_state_path(None, "robot0", ["tcp/127.0.0.1:7447"], [])
    b = resolve_state_path(None, "robot0", ["tcp/127.0.0.1:7448"], [])
    assert a.parent == tmp_path and a.name.startswith("sim-robot0-") and a != b  # two cells, two worlds
    assert a == resolve_state_path(None, "robot0", ["tcp/127.0.0.1:7447"], [])  # a restart finds its own
    assert network_key([], []) == "local"
    assert resolve_state_path(str(tmp_path / "x.json"), "robot0", [], []) == tmp_path / "x.json"
    assert resolve_state_path("none", "robot0", [], []) is None
    monkeypatch.setenv("OBJSCAN_SIM_STATE_FILE", str(tmp_path / "env.json"))
    assert resolve_state_path(None, "robot0", [], []) == tmp_path / "env.json"
    monkeypatch.delenv("OBJSCAN_SIM_STATE_FILE")
    monkeypatch.delenv("OBJSCAN_STATE_DIR")
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    assert resolve_state_path(None, "r/1", [], []) == tmp_path / "xdg" / "objscan" / "sim-r_1-local.json"
