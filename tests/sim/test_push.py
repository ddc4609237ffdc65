"""A closed hand that sweeps through the object pushes it in the twin's MuJoCo mode (what a push relies on);
an open hand passing by leaves it exactly where it stood (grasp approaches are not disturbed)."""

from __future__ import annotations

import numpy as np
import pytest

from services.orchestrator.push import push_sequences
from services.sim.catalogue import load_object
from services.sim.physics import tilt_deg
from services.sim.world import World, default_object_pose, yaw_of
from tests.sim.meshes import write_box_ply

#: a box whose one graspable side (9.9 cm) lies along the line from the base, 14.3 cm across, 10.9 cm tall
SIZE = (0.099, 0.143, 0.109)


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("OBJSCAN_CACHE_DIR", str(tmp_path / "cache"))


def _world(tmp_path) -> World:
    return World(load_object(str(write_box_ply(tmp_path, SIZE))), physics="mujoco",
                 object_pose=default_object_pose(0.60, 0.0))


def _surface(world: World) -> np.ndarray:
    """The box's sides and top as the scans see them (points in ``base``)."""
    rng = np.random.default_rng(0)
    sx, sy, sz = SIZE
    u = rng.uniform(-0.5, 0.5, (6000, 3)) * SIZE
    face = rng.integers(0, 5, 6000)
    for i, (axis, sign) in enumerate(((0, 1), (0, -1), (1, 1), (1, -1), (2, 1))):
        u[face == i, axis] = sign * 0.5 * SIZE[axis]
    u[:, 2] += 0.5 * sz
    T = world.true_object_pose()
    return u @ T[:3, :3].T + T[:3, 3]


def _sweep(world: World, poses: list[np.ndarray], step: float = 0.0005) -> None:
    """Move the hand along straight lines through ``poses`` in set-points ``step`` apart, as the arm streams them."""
    world.move_gripper(poses[0])
    for a, b in zip(poses[:-1], poses[1:], strict=True):
        n = max(1, int(np.ceil(np.linalg.norm(b[:3, 3] - a[:3, 3]) / step)))
        for i in range(1, n + 1):
            T = b.copy()
            T[:3, 3] = a[:3, 3] + (b[:3, 3] - a[:3, 3]) * i / n
            world.move_gripper(T)


@pytest.mark.parametrize("pitched", [False, True])
def test_a_closed_hand_pushed_round_the_near_face_turns_the_box_standing(tmp_path, pitched):
    """Level, or pitched 30 degrees down (the pushes offered near the base), the pad tips drive the box round."""
    world = _world(tmp_path)
    seqs = push_sequences(_surface(world), SIZE[2], 0.08)
    seq = next(s for s in seqs if s.name.endswith("_pitch30") == pitched)
    world.set_gripper_opening(0.0)
    _sweep(world, [seq.above, seq.start, *seq.arc, *seq.retreat])
    T = world.true_object_pose()
    turned = abs(np.degrees(yaw_of(T)))
    assert 35.0 < turned < 70.0, turned  # about half the 90-degree arc
    assert tilt_deg(T) < 2.0  # pushed low: it turns, it does not tip
    assert np.linalg.norm(T[:2, 3] - seq.expected_center[:2]) < 0.05
    assert world.counts["pushes"] > 0


def test_an_open_hand_on_the_same_path_leaves_the_box_where_it_stood(tmp_path):
    world = _world(tmp_path)
    before = world.true_object_pose().copy()
    seq = push_sequences(_surface(world), SIZE[2], 0.08)[0]
    _sweep(world, [seq.above, seq.start, *seq.arc[:3]])  # open (the default): the pads pass as before
    np.testing.assert_array_equal(world.true_object_pose(), before)
    assert world.counts["pushes"] == 0
