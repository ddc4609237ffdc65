"""The world state of the digital twin: table, object and its true pose, arm, gripper and grasp.

The arm's sim driver owns the kinematics: it tells the world the joint positions and the true gripper and
camera poses it computed by FK. The world answers with what the sensors see (``render_frame``) and what
the hands achieve (``close_gripper`` / ``move_gripper`` / ``open_gripper``), with the error profile's
real-world errors. Ground truth (true camera and object poses) only leaves in ``*_true`` fields or a
``ground_truth`` block.

Randomness is split into streams keyed by (seed, kind, index) - a frame's noise by its sequence number and
pose, a grasp's by the grasp count - so re-rendering a frame or replaying a session after a restart gives
the same result regardless of what else was asked in between. That is also why ``snapshot`` /
``World.from_snapshot`` can carry a world across a process restart exactly: the counters are the whole RNG
state, so a restored world draws what the original would have drawn next (services/sim/state_file.py).
"""

from __future__ import annotations

import threading
import time
import zlib

import numpy as np

from common.geometry import invert, make_transform, rotation_about_axis
from common.messages import Intrinsics, RGBDFrame, d435_intrinsics
from services.sim.catalogue import SimObject, load_object, resolve_object
from services.sim.errors import SimError, SimInputError, check_transform
from services.sim.gripper import GraspChecker, GraspOutcome, GripperSpec
from services.sim.object_physics import physics_config_for
from services.sim.physics import PHYSICS_MODES, PhysicsConfig, PhysicsScene, tilt_deg
from services.sim.profiles import ErrorProfile, get_profile
from services.sim.render import RenderResult, RenderScene, SceneBox, TableSpec, render

#: Where an object stands by default (docs/conventions.md).
DEFAULT_OBJECT_XY = (0.50, 0.0)
_STREAM_SESSION, _STREAM_FRAME, _STREAM_GRASP, _STREAM_PLACE, _STREAM_TURN, _STREAM_PUSH = range(6)
#: m between the pads at most for a moving hand to push the object (mujoco mode): a closed hand. An open one
#: passes as before (its approach is the geometric checker's), so grasps are not disturbed on the way in.
PUSH_OPENING = 0.01
_CONTACT_SAMPLES = 40000
#: Version of ``World.snapshot``'s layout; ``from_snapshot`` refuses any other.
SNAPSHOT_FORMAT = 1
#: Geometric failures that are about the approach (the arm brings the pads there), not the contact: the
#: physics mode keeps them from the geometric checker and simulates only what follows.
_APPROACH_FAILURES = ("pad_hits_table", "too_wide", "pad_collides_with_object", "nothing_between_pads")


class SimStateError(SimError):
    """The world cannot do what was asked in its current state (e.g. turning an object it is holding)."""

    code = "bad_sim_state"


def default_object_pose(x: float = DEFAULT_OBJECT_XY[0], y: float = DEFAULT_OBJECT_XY[1],
                        yaw_deg: float = 0.0) -> np.ndarray:
    """T_base_object of an object standing upright on the table at (x, y) with the given yaw."""
    return make_transform(rotation_about_axis([0, 0, 1], np.radians(yaw_deg)), [x, y, 0.0])


def yaw_of(T: np.ndarray) -> float:
    """Yaw (rad) of a pose about base z: the angle of its x axis projected on the table."""
    x = T[:3, 0]
    if abs(x[0]) + abs(x[1]) < 1e-9:  # x points straight up or down: use y instead
        y = T[:3, 1]
        return float(np.arctan2(y[1], y[0]) - np.pi / 2)
    return float(np.arctan2(x[1], x[0]))


def _wrap_deg(a: float) -> float:
    return float((a + 180.0) % 360.0 - 180.0)


class World:
    """Table + one object + arm/gripper state; renders frames and simulates grasps and set-downs.

    Thread-safe (one lock): the service face may call it from worker threads.
    """

    def __init__(self, obj: SimObject | str, *, profile: ErrorProfile | str = "ideal", seed: int = 0,
                 object_pose: np.ndarray | None = None, table: TableSpec | None = None,
                 gripper: GripperSpec | None = None, scale: float | None = None, up_axis: str | None = None,
                 physics: str = "geometric", physics_config: PhysicsConfig | None = None,
                 extras: tuple[SceneBox, ...] = ()):
        """``obj`` is a ``SimObject`` or a HOPE name / mesh path (loaded with ``scale`` and ``up_axis``).

        ``physics``: "geometric" (the fast checker plus the profile's drawn slips, turn and placement errors)
        or "mujoco" (grasp, lift and set-down simulated with contact, ``services/sim/physics.py``).
        ``extras`` adds static scene geometry (walls, other boxes) that is rendered but never grasped.
        """
        if physics not in PHYSICS_MODES:
            raise SimInputError(f"physics must be one of {', '.join(PHYSICS_MODES)}, got {physics!r}",
                                code="bad_value", detail={"physics": str(physics)[:40]})
        self.physics = physics
        self.obj = load_object(obj, scale=scale, up_axis=up_axis) if isinstance(obj, str) else obj
        self.profile = get_profile(profile)
        self.table = table or TableSpec()
        self.extras = tuple(extras)
        self.gripper = gripper = gripper or GripperSpec()
        self._initial_pose = check_transform(default_object_pose() if object_pose is None else object_pose,
                                             "object_pose")
        self._lock = threading.RLock()
        pts, tri, _ = self.obj.sample_surface(_CONTACT_SAMPLES, seed=1)
        self._checker = GraspChecker(self.obj.vertices, self.obj.triangles, pts, self.obj.triangle_normals()[tri],
                                     self.obj.surface_area, gripper)
        self._scene: RenderScene | None = None
        if physics == "mujoco" and physics_config is None and isinstance(obj, str):
            physics_config = physics_config_for(obj)  # the mesh's own mass and friction, when it states them
        self._physics = PhysicsScene(self.obj, gripper, physics_config) if physics == "mujoco" else None
        self.reset(seed)

    # -- state ------------------------------------------------------------------------------------------
    def reset(self, seed: int | None = None) -> None:
        """Back to the start: object at its initial pose, nothing held, gripper open, counters and the
        session's draws (hand-eye error, turn gain) renewed from ``seed`` (default: the current one)."""
        with self._lock:
            if seed is not None:
                if int(seed) < 0:
                    raise SimInputError("seed must be non-negative", code="bad_value", detail={"seed": seed})
                self.seed = int(seed)
            rng = self._rng(_STREAM_SESSION, 0)
            self.hand_eye_error = self.profile.draw_hand_eye_error(rng)
            self.turn_gain = self.profile.draw_turn_gain(rng)
            self.T_base_object = self._initial_pose.copy()
            # the profile's placement: the object stands off where it is expected (drawn last: the
            # session's earlier draws stay as they were for profiles without it)
            self.T_base_object[:2, 3] += self.profile.draw_object_offset(rng)
            self.attached = False
            self.T_gripper_object: np.ndarray | None = None
            self._yaw_at_grasp = 0.0
            self.gripper_opening = self.gripper.max_opening
            self.joint_names: list[str] = []
            self.joint_positions = np.zeros(0)
            self.T_base_gripper: np.ndarray | None = None
            self.T_base_camera: np.ndarray | None = None
            self._force_slip = False
            self._pad_state: tuple[float, ...] | None = None
            self.counts = {"frames": 0, "grasps": 0, "slips": 0, "set_downs": 0, "turns": 0, "pushes": 0}
            self.last_set_down: dict = {}
            self.last_grasp: dict = {}

    def _rng(self, stream: int, index: int, extra: int = 0) -> np.random.Generator:
        return np.random.default_rng(np.random.SeedSequence([self.seed, stream, int(index), int(extra)]))

    @property
    def initial_pose(self) -> np.ndarray:
        """Where the object is meant to stand, before the profile's placement offset: where a cell expects it."""
        return self._initial_pose.copy()

    def true_object_pose(self) -> np.ndarray:
        """T_base_object as it really is (ground truth)."""
        with self._lock:
            return self.T_base_object.copy()

    def set_object_pose(self, T_base_object: np.ndarray) -> None:
        """Place the object (e.g. a scenario's start pose); refused while it is held."""
        T = check_transform(T_base_object, "T_base_object")
        with self._lock:
            if self.attached:
                raise SimStateError("the object is held by the gripper; open it first")
            self.T_base_object = T

    def set_joint_state(self, names: list[str], positions: np.ndarray, *, T_base_gripper: np.ndarray | None = None,
                        T_base_camera: np.ndarray | None = None, gripper_opening: float | None = None) -> None:
        """What the arm's sim driver reports: joints and the true TCP/camera poses from its FK.

        A new TCP pose moves a held object with it.
        """
        pos = np.asarray(positions, dtype=np.float64).reshape(-1)
        if len(names) != pos.shape[0] or not np.all(np.isfinite(pos)):
            raise SimInputError("joint names and positions must match and be finite", code="bad_value")
        Tg = None if T_base_gripper is None else check_transform(T_base_gripper, "T_base_gripper")
        Tc = None if T_base_camera is None else check_transform(T_base_camera, "T_base_camera")
        with self._lock:
            self.joint_names = list(names)
            self.joint_positions = pos
            if Tc is not None:
                self.T_base_camera = Tc
            if gripper_opening is not None and not self.attached:
                self.set_gripper_opening(gripper_opening)
            if Tg is not None:
                self.move_gripper(Tg)

    def set_gripper_opening(self, opening: float) -> None:
        """Open the fingers to ``opening`` (m) without grasping (e.g. pre-grasp); releases a held object."""
        if not np.isfinite(opening) or opening < 0:
            raise SimInputError("gripper opening must be a non-negative number", code="bad_value")
        with self._lock:
            if self.attached:
                self.open_gripper(opening)
            else:
                self.gripper_opening = float(min(opening, self.gripper.max_opening))

    # -- rendering --------------------------------------------------------------------------------------
    def scene(self) -> RenderScene:
        """The ray-casting scene of the current state, rebuilt only when the object has moved."""
        with self._lock:
            if self._scene is None or not np.array_equal(self._scene.T_base_object, self.T_base_object):
                self._scene = RenderScene(self.obj, self.T_base_object, table=self.table, extras=self.extras)
            return self._scene

    def render(self, T_base_camera_true: np.ndarray, intrinsics: Intrinsics | None = None, seq: int = 0,
               ) -> tuple[RenderResult, np.ndarray]:
        """(render result with ground-truth labels, believed T_base_camera) for one capture."""
        T_true = check_transform(T_base_camera_true, "T_base_camera_true")
        K = intrinsics or d435_intrinsics()
        pose_key = zlib.crc32(np.round(T_true, 6).tobytes())
        rng = self._rng(_STREAM_FRAME, seq, pose_key)
        with self._lock:
            scene = self.scene()
            believed = T_true @ self.profile.draw_frame_pose_error(rng) @ self.hand_eye_error
            self.counts["frames"] += 1
        return render(scene, T_true, K, noise=self.profile.camera, rng=rng), believed

    def render_frame(self, T_base_camera_true: np.ndarray | None = None, intrinsics: Intrinsics | None = None,
                     seq: int = 0, *, stamp: float | None = None) -> RGBDFrame:
        """An RGB-D capture from the true camera pose (default: the last one the arm reported).

        ``T_base_camera`` is what the robot believes (hand-eye error and joint noise of the profile);
        ``T_base_camera_true`` is the truth. ``meta`` carries the true object pose as ``T_base_object_true``.
        """
        with self._lock:
            if T_base_camera_true is None:
                if self.T_base_camera is None:
                    raise SimStateError("no camera pose: pass T_base_camera_true or report a joint state first")
                T_base_camera_true = self.T_base_camera
            T_obj = self.T_base_object.copy()
        K = intrinsics or d435_intrinsics()
        res, believed = self.render(T_base_camera_true, K, seq)
        return RGBDFrame(color=res.color, depth=res.depth, depth_scale=res.depth_scale, intrinsics=K,
                         T_base_camera=believed, stamp=time.time() if stamp is None else float(stamp), seq=int(seq),
                         T_base_camera_true=np.asarray(T_base_camera_true, dtype=np.float64).copy(),
                         meta={"source": "sim", "object": self.obj.name, "profile": self.profile.name,
                               "physics": self.physics,
                               "T_base_object_true": T_obj, "object_model": self.object_model()})

    # -- hands ------------------------------------------------------------------------------------------
    def force_next_grasp_slip(self) -> None:
        """Make the next geometrically sound grasp slip (for recovery tests)."""
        with self._lock:
            self._force_slip = True

    def close_gripper(self, T_base_gripper: np.ndarray, opening_cmd: float = 0.0) -> GraspOutcome:
        """Close the fingers at ``T_base_gripper`` towards ``opening_cmd`` (m) and report the grasp.

        A sound grasp attaches the object (pushed onto the gripper's centre line, plus the profile's grasp
        error); a failed one leaves it on the table and says why. A slip (profile chance or forced) is
        reported here as ``reason="slip"`` with the fingers closed.
        """
        Tg = check_transform(T_base_gripper, "T_base_gripper")
        if not np.isfinite(opening_cmd) or opening_cmd < 0:
            raise SimInputError("opening_cmd must be a non-negative number", code="bad_value")
        with self._lock:
            self.T_base_gripper = Tg
            if self.attached:
                return GraspOutcome(False, "already_holding", self.gripper_opening,
                                    "the gripper already holds the object")
            index = self.counts["grasps"]
            self.counts["grasps"] += 1
            rng = self._rng(_STREAM_GRASP, index)
            T_object_gripper = invert(self.T_base_object) @ Tg
            outcome, contact = self._checker.evaluate(T_object_gripper, Tg, self.gripper_opening, opening_cmd)
            if self._physics is not None and outcome.reason not in _APPROACH_FAILURES and not self._force_slip:
                return self._close_physics(Tg, opening_cmd, rng)
            if not outcome.success:
                self.gripper_opening = outcome.width
                return outcome
            slip_draw = rng.random()
            if self._force_slip or slip_draw < self.profile.slip_prob:
                forced = self._force_slip
                self._force_slip = False
                self.counts["slips"] += 1
                self.gripper_opening = float(min(opening_cmd, self.gripper_opening))
                # the object squirts out and settles a little off where it stood
                nudge = rng.normal(0.0, 0.002, 2)
                self.T_base_object = self.T_base_object.copy()
                self.T_base_object[:2, 3] += nudge
                return GraspOutcome(False, "slip", self.gripper_opening,
                                    "the object slipped out of the fingers" + (" (forced)" if forced else ""))
            T_gripper_object = invert(Tg) @ self.T_base_object
            T_gripper_object[1, 3] -= contact.center_offset_y
            p = self.profile
            if p.grasp_pivot_sigma_deg > 0 or p.grasp_shift_sigma_m > 0:
                pivot = rotation_about_axis([0, 1, 0], np.radians(rng.normal(0.0, p.grasp_pivot_sigma_deg)))
                shift = np.array([rng.normal(0.0, p.grasp_shift_sigma_m), 0.0, rng.normal(0.0, p.grasp_shift_sigma_m)])
                T_gripper_object = make_transform(pivot, shift) @ T_gripper_object
            self.T_gripper_object = T_gripper_object
            self.attached = True
            self._yaw_at_grasp = yaw_of(self.T_base_object)
            self.T_base_object = Tg @ T_gripper_object
            self.gripper_opening = outcome.width
            return outcome

    def _close_physics(self, Tg: np.ndarray, opening_cmd: float, rng: np.random.Generator) -> GraspOutcome:
        """The mujoco mode's grasp: close, lift and hold in the contact simulation (lock held)."""
        result = self._physics.grasp(self.T_base_object, Tg, self.gripper_opening, opening_cmd, rng)
        self.gripper_opening = result.width
        self.last_grasp = {"reason": result.reason, "in_hand_turn_deg": result.in_hand_turn_deg,
                           "width": result.width}
        if not result.held:
            if result.reason == "slip":
                self.counts["slips"] += 1
            self.T_base_object = result.T_base_object  # wherever it fell or was pushed
            return GraspOutcome(False, result.reason, result.width, result.message)
        self.T_gripper_object = result.T_gripper_object
        self._pad_state = result.pad_state
        self.attached = True
        self._yaw_at_grasp = yaw_of(self.T_base_object)
        self.T_base_object = Tg @ result.T_gripper_object
        return GraspOutcome(True, "ok", result.width, result.message)

    def move_gripper(self, T_base_gripper: np.ndarray) -> None:
        """The TCP moved (true pose from the arm's FK); a held object follows it. In the mujoco mode a closed
        hand (pads at most ``PUSH_OPENING`` apart) that sweeps through the object pushes it."""
        Tg = check_transform(T_base_gripper, "T_base_gripper")
        with self._lock:
            before = self.T_base_gripper
            self.T_base_gripper = Tg
            if self.attached:
                self.T_base_object = Tg @ self.T_gripper_object
            elif (self._physics is not None and before is not None and self.gripper_opening <= PUSH_OPENING
                  and self._physics.sweeps_near(self.T_base_object, before, Tg)):
                rng = self._rng(_STREAM_PUSH, self.counts.get("pushes", 0))
                T = self._physics.push(self.T_base_object, before, Tg, self.gripper_opening, rng)
                if not np.array_equal(T, self.T_base_object):
                    self.counts["pushes"] = self.counts.get("pushes", 0) + 1
                    self.T_base_object = T

    def open_gripper(self, opening: float | None = None) -> dict:
        """Open the fingers (default fully). A held object is set down: upright on the table (bottom at
        z = 0, rotation reduced to yaw) where it was released, with the profile's turn and placement errors.

        Returns a ground-truth summary of the set-down (empty when nothing was held).
        """
        with self._lock:
            target = self.gripper.max_opening if opening is None else float(opening)
            if not np.isfinite(target) or target < 0:
                raise SimInputError("gripper opening must be a non-negative number", code="bad_value")
            self.gripper_opening = min(target, self.gripper.max_opening)
            if not self.attached:
                return {}
            released = self.T_base_object
            commanded = _wrap_deg(np.degrees(yaw_of(released) - self._yaw_at_grasp))
            rng = self._rng(_STREAM_PLACE, self.counts["set_downs"])
            if self._physics is not None and self._pad_state is not None and self.T_base_gripper is not None:
                return self._set_down_physics(commanded, rng)
            achieved, shift, bounced = self.profile.draw_set_down(commanded, self.turn_gain, rng)
            self.counts["set_downs"] += 1
            yaw = self._yaw_at_grasp + np.radians(achieved)
            xy = released[:2, 3] + shift
            self.T_base_object = default_object_pose(xy[0], xy[1], np.degrees(yaw))
            self.attached = False
            self.T_gripper_object = None
            self.last_set_down = {"gripper_turn_deg": commanded, "achieved_turn_deg": achieved,
                                  "shift_m": shift.tolist(), "bounced": bounced}
            return dict(self.last_set_down)

    def _set_down_physics(self, commanded: float, rng: np.random.Generator) -> dict:
        """The mujoco mode's set-down: open the pads where the hand is and let the object come to rest."""
        res = self._physics.set_down(self.T_base_gripper, self.T_gripper_object, self._pad_state, rng)
        self.counts["set_downs"] += 1
        before = self.T_base_object
        self.T_base_object = res.T_base_object
        self.attached = False
        self.T_gripper_object = None
        self._pad_state = None
        achieved = _wrap_deg(np.degrees(yaw_of(res.T_base_object)) - np.degrees(self._yaw_at_grasp))
        self.last_set_down = {"gripper_turn_deg": commanded, "achieved_turn_deg": achieved,
                              "shift_m": (res.T_base_object[:2, 3] - before[:2, 3]).tolist(),
                              "bounced": res.bounce_m > 0.003, "bounce_m": res.bounce_m,
                              "tilt_deg": res.tilt_deg, "toppled": res.toppled, "settled": res.settled,
                              "physics": "mujoco"}
        return dict(self.last_set_down)

    def turn_object(self, angle_deg: float, rng: np.random.Generator | None = None) -> float:
        """Turn the object on the table by ``angle_deg`` about the table normal through its footprint centre,
        as a person would, with the profile's turn/placement errors. Returns the achieved turn (deg)."""
        if not np.isfinite(angle_deg):
            raise SimInputError("turn angle must be finite", code="bad_value")
        with self._lock:
            if self.attached:
                raise SimStateError("the object is held by the gripper; open it before turning it by hand")
            if rng is None:
                rng = self._rng(_STREAM_TURN, self.counts["turns"])
            self.counts["turns"] += 1
            achieved, shift, bounced = self.profile.draw_set_down(float(angle_deg), self.turn_gain, rng)
            T = self.T_base_object
            x, y = T[0, 3] + shift[0], T[1, 3] + shift[1]
            self.T_base_object = default_object_pose(x, y, np.degrees(yaw_of(T)) + achieved)
            self.last_set_down = {"commanded_turn_deg": float(angle_deg), "achieved_turn_deg": achieved,
                                  "shift_m": shift.tolist(), "bounced": bounced}
            return achieved

    def object_model(self) -> dict:
        """Where the ground-truth mesh comes from: enough for an evaluator to ``load_object`` it again."""
        o = self.obj
        return {"name": o.name, "source": None if o.source is None else str(o.source), "scale": o.scale,
                "up_axis": o.up_axis}

    # -- reporting --------------------------------------------------------------------------------------
    def state(self) -> dict:
        """JSON-able snapshot; ground truth is under ``ground_truth``."""
        with self._lock:
            def m(T):
                return None if T is None else np.asarray(T).tolist()
            return {
                "object": self.obj.name,
                "object_model": self.object_model(),
                "profile": self.profile.name,
                "pose_accuracy": self.profile.pose_accuracy().to_dict(),  # what the twin's arm states
                "turn_accuracy_deg": self.profile.turn_accuracy_deg(),  # ... and how well it turns the object
                "physics": self.physics,
                "seed": self.seed,
                "attached": self.attached,
                "object_tilt_deg": tilt_deg(self.T_base_object),
                "gripper_opening": self.gripper_opening,
                "joint_names": list(self.joint_names),
                "joint_positions": self.joint_positions.tolist(),
                "T_base_gripper": m(self.T_base_gripper),
                "counts": dict(self.counts),
                "ground_truth": {
                    "T_base_object": m(self.T_base_object),
                    "T_base_camera": m(self.T_base_camera),
                    "T_gripper_object": m(self.T_gripper_object),
                    "hand_eye_error": m(self.hand_eye_error),
                    "turn_gain": self.turn_gain,
                    "last_set_down": dict(self.last_set_down),
                    "last_grasp": dict(self.last_grasp),
                },
            }

    # -- persistence ------------------------------------------------------------------------------------
    def snapshot(self) -> dict:
        """Everything that makes this world what it is now, JSON-able and exact (floats round-trip).

        The object is stored by where its mesh comes from (``object_model``), the profile by name; the
        table and gripper are the defaults (a world built with other specs is restored with the defaults).
        The counters are stored, so the restored world's random draws continue where these left off.
        """
        with self._lock:
            def m(T):
                return None if T is None else np.asarray(T, dtype=np.float64).tolist()
            return {
                "format": SNAPSHOT_FORMAT,
                "object_model": self.object_model(),
                "profile": self.profile.name,
                "pose_accuracy": self.profile.pose_accuracy().to_dict(),  # what the twin's arm states
                "physics": self.physics,
                "pad_state": None if self._pad_state is None else list(self._pad_state),
                "seed": self.seed,
                "initial_pose": m(self._initial_pose),
                "T_base_object": m(self.T_base_object),
                "attached": bool(self.attached),
                "T_gripper_object": m(self.T_gripper_object),
                "yaw_at_grasp": float(self._yaw_at_grasp),
                "gripper_opening": float(self.gripper_opening),
                "joint_names": list(self.joint_names),
                "joint_positions": self.joint_positions.tolist(),
                "T_base_gripper": m(self.T_base_gripper),
                "T_base_camera": m(self.T_base_camera),
                "force_slip": bool(self._force_slip),
                "counts": {k: int(v) for k, v in self.counts.items()},
                "last_set_down": _plain(self.last_set_down),
                "hand_eye_error": m(self.hand_eye_error),
                "turn_gain": float(self.turn_gain),
            }

    @classmethod
    def from_snapshot(cls, snap: dict) -> World:
        """The world ``snapshot()`` described: same object, profile, seed, poses, grasp, counters.

        Raises ``SimStateError`` (code ``bad_snapshot``) when the snapshot is not one this version wrote
        or its object can no longer be loaded; a bad pose inside it raises ``SimInputError``.
        """
        if not isinstance(snap, dict) or snap.get("format") != SNAPSHOT_FORMAT:
            got = snap.get("format") if isinstance(snap, dict) else type(snap).__name__
            raise SimStateError(f"not a world snapshot of format {SNAPSHOT_FORMAT} (got {got!r})",
                                code="bad_snapshot")
        try:
            model = snap["object_model"]
            world = cls(_object_from_model(model), profile=str(snap["profile"]), seed=int(snap["seed"]),
                        object_pose=np.asarray(snap["initial_pose"], dtype=np.float64),
                        physics=str(snap.get("physics", "geometric")))
            with world._lock:
                world.T_base_object = check_transform(snap["T_base_object"], "T_base_object")
                world.attached = bool(snap["attached"])
                Tgo = snap["T_gripper_object"]
                world.T_gripper_object = None if Tgo is None else check_transform(Tgo, "T_gripper_object")
                if world.attached and world.T_gripper_object is None:
                    raise SimInputError("a held object needs T_gripper_object", code="bad_value")
                world._yaw_at_grasp = float(snap["yaw_at_grasp"])
                world.gripper_opening = float(snap["gripper_opening"])
                world.joint_names = [str(n) for n in snap["joint_names"]]
                world.joint_positions = np.asarray(snap["joint_positions"], dtype=np.float64).reshape(-1)
                for name in ("T_base_gripper", "T_base_camera"):
                    T = snap[name]
                    setattr(world, name, None if T is None else check_transform(T, name))
                world._force_slip = bool(snap["force_slip"])
                pads = snap.get("pad_state")
                world._pad_state = None if pads is None else tuple(float(q) for q in pads)
                world.counts.update({str(k): int(v) for k, v in snap["counts"].items()})
                world.last_set_down = dict(snap["last_set_down"])
                world.hand_eye_error = check_transform(snap["hand_eye_error"], "hand_eye_error")
                world.turn_gain = float(snap["turn_gain"])
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise SimStateError(f"world snapshot is incomplete or malformed: {type(exc).__name__}: {exc}",
                                code="bad_snapshot") from None
        return world


def _object_from_model(model: dict) -> SimObject:
    """Load the object an ``object_model`` names: by its HOPE name when that still resolves to the same
    mesh (so its name is kept), else from the mesh file."""
    name, source = str(model["name"]), model.get("source")
    scale, up_axis = model.get("scale"), model.get("up_axis")
    try:
        _, path, _ = resolve_object(name)
        by_name = source is None or str(path) == str(source)
    except SimError:
        by_name = source is None
    obj = load_object(name if by_name else str(source), scale=scale, up_axis=up_axis)
    obj.name = name
    return obj


def _plain(obj):  # noqa: ANN001, ANN202 - JSON-able copy of a small nested dict of numbers/lists
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj
