"""Collision checks before any motion (pinocchio geometry + coal): this stands in for MoveIt's planning scene.

The world is the arm's own collision meshes (with the fingers at the commanded opening), the table (a box
whose top is the plane z = 0 of ``base``) and an optional box around the object. Checked pairs:

- every arm/gripper/camera-mount body against the table, except ``robot1/link1`` which stands on it;
- every body against the object box, when one is set (the hand may be allowed to touch it: grasping);
- self-collision between bodies that are not neighbours on the chain. Neighbours (a link and the next
  one, and everything rigidly attached after joint 6: end link, gripper base, camera mount, fingers) touch
  by construction in the PAPRAS meshes and are ignored.

A colliding configuration or motion is refused with ``CollisionError`` naming the two bodies.

Thread safety: the arm service checks motions in executor threads while ``arm/scene`` may
change the object box. Pinocchio's geometry model and data are not safe to mutate during a check (a box
changed mid-check corrupted the heap and killed the arm process), so one lock covers every scene change
and every query, and a trajectory is checked against one scene from its first sample to its last.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import coal
import numpy as np
import pinocchio as pin

from services.arm.errors import BadCommand, CollisionError
from services.arm.kinematics import Kinematics
from services.arm.motion import JointTrajectory

TABLE = "table"
OBJECT = "object"
HAND_CHAIN_INDEX = 6  # bodies on joint 6 and after (end link, gripper, camera mount, fingers) move together
F = TypeVar("F", bound=Callable[..., Any])


def _exclusive(method: F) -> F:
    """Run ``method`` holding the world's lock (re-entrant: a trajectory check calls ``first_contact``)."""

    @functools.wraps(method)
    def locked(self: CollisionWorld, *args: Any, **kwargs: Any) -> Any:
        with self._lock:
            return method(self, *args, **kwargs)

    return locked  # type: ignore[return-value]


@dataclass
class CollisionConfig:
    """The static scene and how densely motions are checked.

    Table defaults follow docs/conventions.md (1.2 m x 1.2 m centred at (0.4, 0, 0), top at z = 0).
    """

    table_center_xy: tuple[float, float] = (0.4, 0.0)
    table_size_xy: tuple[float, float] = (1.2, 1.2)
    table_thickness: float = 0.05
    margin: float = 0.003  # m of clearance required (coal security margin)
    check_rate_hz: float = 50.0  # trajectory samples checked per second of motion ...
    max_joint_step: float = 0.02  # ... and at least this dense in joint space (rad)
    self_collision: bool = True


@dataclass
class Contact:
    """A colliding pair of bodies (link names of the URDF or ``table`` / ``object``)."""

    body_a: str
    body_b: str


class CollisionWorld:
    """The arm, the table and an optional object box, ready to answer "does this collide?"."""

    def __init__(self, kinematics: Kinematics, config: CollisionConfig | None = None):
        self.kin = kinematics
        self._lock = threading.RLock()
        self.config = config or CollisionConfig()
        cfg = self.config
        self.model = kinematics.full_model
        self.data = self.model.createData()
        self.geom = pin.buildGeomFromUrdf(
            self.model,
            str(kinematics.config.urdf_path),
            pin.COLLISION,
            package_dirs=[str(kinematics.config.package_dir)],
        )
        self._robot_geoms = list(range(self.geom.ngeoms))
        self._body = {i: self.model.frames[self.geom.geometryObjects[i].parentFrame].name for i in self._robot_geoms}
        sx, sy = cfg.table_size_xy
        table = pin.GeometryObject(
            TABLE,
            0,
            0,
            pin.SE3(np.eye(3), np.array([*cfg.table_center_xy, -cfg.table_thickness / 2])),
            coal.Box(sx, sy, cfg.table_thickness),
        )
        self._table = self.geom.addGeometryObject(table)
        self._body[self._table] = TABLE
        self._object: int | None = None
        self._pairs_base = self._static_pairs()
        self._object_pairs: list[tuple[int, int]] = []
        self._rebuild()

    # ------------------------------------------------------------------ scene
    def _chain_index(self, gid: int) -> int:
        return min(int(self.geom.geometryObjects[gid].parentJoint), HAND_CHAIN_INDEX)

    def _static_pairs(self) -> list[tuple[int, int]]:
        pairs = [(i, self._table) for i in self._robot_geoms if self._body[i] != "robot1/link1"]
        if self.config.self_collision:
            for a in self._robot_geoms:
                for b in self._robot_geoms:
                    if a < b and abs(self._chain_index(a) - self._chain_index(b)) >= 2:
                        pairs.append((a, b))
        return pairs

    def _rebuild(self) -> None:
        self.geom.removeAllCollisionPairs()
        self._pair_list = self._pairs_base + self._object_pairs
        for a, b in self._pair_list:
            self.geom.addCollisionPair(pin.CollisionPair(a, b))
        self.gdata = pin.GeometryData(self.geom)
        for req in self.gdata.collisionRequests:
            req.security_margin = self.config.margin
        self._hand_pairs = {
            k
            for k, (a, b) in enumerate(self._pair_list)
            if self._body[b] == OBJECT and self._chain_index(a) >= HAND_CHAIN_INDEX
        }

    @_exclusive
    def set_object_box(self, center: np.ndarray, size: np.ndarray, yaw: float = 0.0) -> None:
        """Add (or move) the box around the object: ``center`` of the box in ``base``, full ``size`` (m)."""
        c = np.asarray(center, dtype=np.float64)
        s = np.asarray(size, dtype=np.float64)
        if c.shape != (3,) or s.shape != (3,) or not np.all(np.isfinite(c)) or not np.all(np.isfinite(s)):
            raise BadCommand("object box needs a 3-vector center and size", code="bad_shape")
        if np.any(s <= 0) or not np.isfinite(yaw):
            raise BadCommand("object box size must be positive", code="bad_value", detail={"size": s.tolist()})
        R = pin.utils.rotate("z", float(yaw))
        if self._object is not None:
            self.clear_object()
        obj = pin.GeometryObject(OBJECT, 0, 0, pin.SE3(R, c), coal.Box(*s))
        self._object = self.geom.addGeometryObject(obj)
        self._body[self._object] = OBJECT
        self._object_pairs = [(i, self._object) for i in self._robot_geoms]
        self._rebuild()

    def set_object_footprint(self, xy: np.ndarray, height: float, radius: float, padding: float = 0.01) -> None:
        """Box standing on the table around an object of ``radius`` and ``height`` at ``xy``."""
        side = 2.0 * (radius + padding)
        h = height + padding
        self.set_object_box(np.array([xy[0], xy[1], h / 2.0]), np.array([side, side, h]))

    @_exclusive
    def clear_object(self) -> None:
        """Remove the object box (e.g. while the object is in the hand)."""
        if self._object is None:
            return
        self.geom.removeGeometryObject(OBJECT)
        self._body.pop(self._object, None)
        self._object = None
        self._object_pairs = []
        self._rebuild()

    @property
    def has_object(self) -> bool:
        return self._object is not None

    # ------------------------------------------------------------------ queries
    @_exclusive
    def first_contact(self, q: np.ndarray, opening: float = 0.0, allow_hand_object: bool = False) -> Contact | None:
        """The first colliding pair at arm configuration ``q`` with the fingers at ``opening``, or None."""
        qf = self.kin.full_q(q, opening=opening)
        if not allow_hand_object:
            if not pin.computeCollisions(self.model, self.data, self.geom, self.gdata, qf, True):
                return None
        else:
            pin.updateGeometryPlacements(self.model, self.data, self.geom, self.gdata, qf)
        results = self.gdata.collisionResults
        for k, (a, b) in enumerate(self._pair_list):
            if allow_hand_object and k in self._hand_pairs:
                continue
            if allow_hand_object:
                if not pin.computeCollision(self.geom, self.gdata, k):
                    continue
            elif not results[k].isCollision():
                continue
            return Contact(self._body[a], self._body[b])
        return None

    @_exclusive
    def check_configuration(self, q: np.ndarray, opening: float = 0.0, allow_hand_object: bool = False) -> None:
        """Raise ``CollisionError`` naming the pair if ``q`` collides."""
        c = self.first_contact(q, opening, allow_hand_object)
        if c is not None:
            raise CollisionError(
                f"{c.body_a} collides with {c.body_b}",
                detail={"link_a": c.body_a, "link_b": c.body_b, "q": np.round(q, 4).tolist()},
            )

    @_exclusive
    def check_trajectory(
        self, trajectory: JointTrajectory, opening: float = 0.0, allow_hand_object: bool = False
    ) -> int:
        """Check the motion densely (rate and joint-step bounds); returns the number of checked samples."""
        cfg = self.config
        s = trajectory.sample(cfg.check_rate_hz)
        Q = s.q
        # densify where neighbouring samples move more than max_joint_step
        dense = [Q[0]]
        for a, b in zip(Q[:-1], Q[1:], strict=True):
            n = int(np.ceil(np.max(np.abs(b - a)) / cfg.max_joint_step))
            for k in range(1, max(n, 1) + 1):
                dense.append(a + (b - a) * k / max(n, 1))
        for i, q in enumerate(dense):
            c = self.first_contact(q, opening, allow_hand_object)
            if c is not None:
                t = float(trajectory.duration * i / max(len(dense) - 1, 1))
                raise CollisionError(
                    f"motion collides: {c.body_a} hits {c.body_b}",
                    detail={
                        "link_a": c.body_a,
                        "link_b": c.body_b,
                        "t_approx": round(t, 3),
                        "q": np.round(q, 4).tolist(),
                    },
                )
        return len(dense)
