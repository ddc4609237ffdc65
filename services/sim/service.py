"""The digital twin's Zenoh face (used only by the ``sim`` backends of camera and arm, and by tests).

- ``sim/render`` (``CaptureRequest``) → ``RGBDFrame`` from the camera pose the arm last reported, with the
  believed pose (profile errors) and the true one (ground truth).
- ``sim/joints`` (``JointState`` with true TCP/camera poses) → ``Ok``: the arm's sim driver streams set-points
  as requests, so they arrive in order and a move has reached the twin when the arm answers.
- ``sim/gripper`` (``GripperRequest``) → ``GripperResult``: closing at the current TCP grasps (or not, and
  why); opening sets a held object down with the profile's errors.
- ``sim/world`` (``Request``, ``params.op``): ``state``, ``reset`` (object, profile, seed), ``force_slip``,
  ``turn`` (by hand), ``gt_points`` (ground-truth surface samples in ``base``). Ground truth only. A reset
  loads its object only from the twin's configured roots (``object_roots.py``): one ``object_not_found``
  answer for a path outside them and for one that is not there.

The world survives the twin: every change is written to a state file before the reply goes out (joint
set-points, which stream at up to 100 Hz, at most ``JOINTS_SAVE_DELAY_S`` later, and always before the
next frame is rendered), and a restarted twin loads it (services/sim/state_file.py: where, and how to
start fresh). The arm's twin link re-sends its joints when the twin comes back.
"""

from __future__ import annotations

import asyncio
import logging

import numpy as np

from common import keys
from common.api import CaptureRequest, GripperRequest, GripperResult
from common.codec import Message
from common.errors import InvalidRequest
from common.log import event
from common.messages import D435_COLOR_SIZES, JointState, Ok, Request, RGBDFrame, d435_intrinsics
from common.runtime import QueryContext, Service, run_service, service_arg_parser, settings_from_args
from services.sim.demo_objects import DEFAULT_OBJECT
from services.sim.object_roots import ObjectRoots
from services.sim.render import warm_up
from services.sim.state_file import StateFile, resolve_state_path
from services.sim.world import World, default_object_pose

log = logging.getLogger("objscan.sim")

#: Joint set-points are saved at most this long after they arrive (a render saves them at once).
JOINTS_SAVE_DELAY_S = 0.2


class SimService(Service):
    name = "sim"

    async def setup(self) -> None:
        opts = self.settings.options
        z = self.settings.zenoh
        path = resolve_state_path(opts.get("state_file"), self.robot, list(z.connect), list(z.listen))
        self.state_file = StateFile(path) if path is not None else None
        self.object_roots = ObjectRoots.configured(opts.get("object"), opts.get("object_dirs") or ())
        self.restored = False
        self.state_error = ""
        self._joints_dirty = False
        self._joints_flush: asyncio.Task | None = None
        self._long_ops = 0  # world changes running in a worker thread (they hold the world's lock and save after)
        doc = None
        if self.state_file is not None and not opts.get("fresh"):
            doc = await self.run_cpu(self.state_file.load)  # a broken file stops the start (typed error)
        if doc is not None:
            self.world = await self.run_cpu(World.from_snapshot, doc["world"])
            self.seq = int(doc.get("seq", 0))
            self.restored = True
            event(log, "world restored from the state file", path=str(path), object=self.world.obj.name,
                  frames=self.seq, attached=self.world.attached)
        else:
            self.world = await self.run_cpu(lambda: World(opts.get("object", DEFAULT_OBJECT),
                                                          profile=opts.get("profile", "ideal"),
                                                          seed=int(opts.get("seed", 0)),
                                                          physics=opts.get("physics", "geometric"),
                                                          scale=opts.get("scale"), up_axis=opts.get("up_axis")))
            self.seq = 0
        self._persist()
        await self.run_cpu(warm_up, self.world.obj)  # compiled kernels before the first frame is asked for
        self._world_lock = asyncio.Lock()
        r = self.robot
        self.queryable(keys.sim(r, "render"), self.render)
        self.queryable(keys.sim(r, "joints"), self.joints)
        self.queryable(keys.sim(r, "gripper"), self.gripper)
        self.queryable(keys.sim(r, "world"), self.world_op)

    async def render(self, msg: Message | None, ctx: QueryContext) -> RGBDFrame:
        width = msg.width if isinstance(msg, CaptureRequest) and msg.width else 640
        height = msg.height if isinstance(msg, CaptureRequest) and msg.height else 480
        if (width, height) not in D435_COLOR_SIZES:
            raise InvalidRequest("the twin renders the D435 presets 640x480 and 848x480",
                                 detail={"width": width, "height": height})
        self.seq += 1
        frame = await self.run_cpu(self.world.render_frame, None, d435_intrinsics(width, height), self.seq)
        self._persist()  # the frame counter keys the next frame's noise: a restart must not repeat a frame
        return frame

    async def joints(self, msg: Message | None, ctx: QueryContext) -> Ok:
        if not isinstance(msg, JointState):
            raise InvalidRequest("expected a JointState", detail={"got": type(msg).__name__})
        self.world.set_joint_state(msg.names, msg.position, T_base_gripper=msg.T_base_gripper,
                                   T_base_camera=msg.T_base_camera)
        self._joints_changed()
        return Ok()

    async def gripper(self, msg: Message | None, ctx: QueryContext) -> GripperResult:
        if not isinstance(msg, GripperRequest):
            raise InvalidRequest("expected a GripperRequest", detail={"got": type(msg).__name__})
        w = self.world
        if msg.opening < w.gripper_opening - 1e-4 and not w.attached:
            if w.T_base_gripper is None:
                raise InvalidRequest("no TCP pose reported yet: move the arm before closing the gripper")
            outcome = await self._long_op(w.close_gripper, w.T_base_gripper, msg.opening)
            return GripperResult(opening=float(outcome.width), holding=bool(outcome.success), reason=outcome.reason)
        if w.attached and msg.opening <= w.gripper_opening + 1e-4:
            return GripperResult(opening=float(w.gripper_opening), holding=True, reason="already_holding")
        released = await self._long_op(w.open_gripper, msg.opening)
        return GripperResult(opening=float(w.gripper_opening), holding=False,
                             reason="released" if released else "opened")

    async def world_op(self, msg: Message | None, ctx: QueryContext) -> Message:
        params = msg.params if isinstance(msg, Request) else {}
        op = params.get("op", "state")
        if op == "state":
            return Ok(info=self.world.state())
        if op == "reset":
            async with self._world_lock:
                w = self.world
                current = (w.obj.name, None if w.obj.source is None else str(w.obj.source))
                requested = params.get("object", w.obj.name)
                checked = self.object_roots.check(requested, current)
                scale = _number(params, "scale", None, 1e-6, 1000.0) if params.get("scale") is not None else None
                up_axis = _up_axis(params.get("up_axis"))
                same_form = (scale is None or scale == w.obj.scale) and \
                    (up_axis is None or up_axis == str(w.obj.up_axis).strip().lower().lstrip("+"))
                # the object the world holds is reused as it is (a mesh given by path has only a stem as name),
                # unless it is asked in other units or another upright axis: then reloaded from its file
                reuse = checked in current
                obj = checked if not reuse else w.obj.copy() if same_form else (current[1] or checked)
                profile = params.get("profile", w.profile.name)
                seed = int(params.get("seed", w.seed))
                physics = str(params.get("physics", w.physics))
                pose = None
                if "x" in params or "y" in params or "yaw_deg" in params:
                    pose = default_object_pose(float(params.get("x", 0.6)), float(params.get("y", 0.0)),
                                               float(params.get("yaw_deg", 0.0)))
                new = await self.run_cpu(lambda: World(obj, profile=profile, seed=seed, object_pose=pose,
                                                       physics=physics, scale=scale, up_axis=up_axis))
                if w.joint_names:  # the arm has not moved: the new world knows where it is
                    new.set_joint_state(w.joint_names, w.joint_positions, T_base_gripper=w.T_base_gripper,
                                        T_base_camera=w.T_base_camera)
                self.world, self.seq = new, 0
                self._persist()
            return Ok(info=self.world.state())
        if op == "force_slip":
            self.world.force_next_grasp_slip()
            self._persist()
            return Ok(info={"armed": True})
        if op == "turn":
            achieved = self.world.turn_object(_number(params, "angle_deg", 30.0, -360.0, 360.0))
            self._persist()
            return Ok(info={"achieved_turn_deg": achieved})
        if op == "gt_points":
            n = int(_number(params, "n", 50000, 1, 1_000_000))
            pts = self.world.obj.gt_points(n)
            T = self.world.true_object_pose()
            xyz = pts @ T[:3, :3].T + T[:3, 3]
            return Ok(info={"xyz": np.ascontiguousarray(xyz, dtype=np.float64), "T_base_object": T,
                            "object": self.world.obj.name, "ground_truth": True})
        raise InvalidRequest(f"unknown sim world op {op!r}",
                             detail={"ops": ["state", "reset", "force_slip", "turn", "gt_points"]})

    # ------------------------------------------------------------------------------ state file
    def _persist(self) -> None:
        """Write the world now (on the loop thread, so saves happen in order and the last one is newest).

        A failed write is logged and shown in health, not raised: the twin keeps serving, it just would not
        survive a crash."""
        self._joints_dirty = False
        if self.state_file is None:
            return
        try:
            self.state_file.save(self.world.snapshot(), seq=self.seq, robot=self.robot)
            self.state_error = ""
        except OSError as exc:
            if not self.state_error:
                event(log, "could not save the world state", logging.ERROR, path=str(self.state_file.path),
                      error=str(exc))
            self.state_error = str(exc)

    def _joints_changed(self) -> None:
        """Set-points stream fast: save once they pause for ``JOINTS_SAVE_DELAY_S`` (or with the next event)."""
        self._joints_dirty = True
        if self.state_file is not None and (self._joints_flush is None or self._joints_flush.done()):
            self._joints_flush = self.spawn(self._flush_joints_later())

    async def _flush_joints_later(self) -> None:
        await asyncio.sleep(JOINTS_SAVE_DELAY_S)
        # a grasp being evaluated holds the world's lock for seconds: do not block the loop on it, its own
        # save afterwards includes the joints
        if self._joints_dirty and not self._long_ops:
            self._persist()

    async def _long_op(self, fn, *args):  # noqa: ANN001, ANN202
        """Run a world change in a worker thread, then save the world."""
        self._long_ops += 1
        try:
            return await self.run_cpu(fn, *args)
        finally:
            self._long_ops -= 1
            self._persist()

    def stop(self) -> None:
        self._clean_stop = True
        super().stop()

    async def teardown(self) -> None:
        # a clean stop ends the world (the next start is fresh); a killed twin never gets here
        state_file = getattr(self, "state_file", None)
        if getattr(self, "_clean_stop", False) and state_file is not None and hasattr(self, "world"):
            state_file.discard()

    def health_info(self) -> dict[str, object]:
        info: dict[str, object] = {"object": self.world.obj.name, "profile": self.world.profile.name,
                                   "physics": self.world.physics,
                                   "frames": self.seq, "restored": self.restored,
                                   "state_file": None if self.state_file is None else str(self.state_file.path)}
        if self.state_error:
            info["state_error"] = self.state_error
        return info


def _number(params: dict, name: str, default: float, lo: float, hi: float) -> float:
    """A numeric request parameter, checked: a bad one is the caller's error, not the twin's."""
    value = params.get(name, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
        raise InvalidRequest(f"{name} must be a number in [{lo}, {hi}]", detail={name: repr(value)[:40]})
    return float(value)


def _up_axis(value: object) -> str | None:
    """A request's ``up_axis`` (None: the file's own), checked like the catalogue does."""
    if value is None:
        return None
    if not isinstance(value, str) or value.strip().lower().lstrip("+") not in ("x", "y", "z", "-x", "-y", "-z"):
        raise InvalidRequest("up_axis must be one of x, y, z, -x, -y, -z", detail={"up_axis": repr(value)[:40]})
    return value.strip().lower().lstrip("+")


def main() -> None:
    p = service_arg_parser("objscan digital twin (simulated table, object, arm, gripper and D435)")
    p.add_argument("--object", default=DEFAULT_OBJECT,
                   help="the object to start with: a demo object (carton, can, flat_box), a HOPE name or a mesh "
                        "path (default: %(default)s)")
    p.add_argument("--object-dir", action="append", default=[], metavar="DIR",
                   help="a folder whose meshes a reset request may name, by path or by the name of a sub-folder or "
                        "mesh file in it (repeatable; also $OBJSCAN_SIM_OBJECT_DIRS). Besides these, only the demo "
                        "objects, HOPE objects, the --object given here and the world's current object can be "
                        "loaded")
    p.add_argument("--scale", type=float, default=None,
                   help="the --object mesh's units in metres, e.g. 0.001 for millimetres (default: the file's own: "
                        "HOPE 0.01, other meshes 1)")
    p.add_argument("--up-axis", default=None, metavar="AXIS",
                   help="the --object mesh's upright axis: x, y, z, -x, -y or -z (default: HOPE y, other meshes z)")
    p.add_argument("--profile", default="ideal", help="error profile: ideal | hand-turned | realistic | robot-turned")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--physics", default="geometric", choices=["geometric", "mujoco"],
                   help="grasp/set-down model: geometric checker + drawn errors, or MuJoCo contact physics")
    p.add_argument("--state-file", default=None,
                   help="where the world is kept across restarts ('none': nowhere; default: env "
                        "OBJSCAN_SIM_STATE_FILE, else $OBJSCAN_STATE_DIR/sim-ROBOT-NETWORK.json; see docs/sim.md)")
    p.add_argument("--fresh", action="store_true",
                   help="ignore a saved world and start from --object/--profile/--seed (overwrites the file)")
    args = p.parse_args()
    run_service(lambda: SimService(settings_from_args(args, object=args.object, object_dirs=args.object_dir,
                                                      scale=args.scale, up_axis=args.up_axis,
                                                      profile=args.profile,
                                                      seed=args.seed, physics=args.physics,
                                                      state_file=args.state_file,
                                                      fresh=args.fresh)))
