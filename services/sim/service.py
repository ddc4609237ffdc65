"""The digital twin's Zenoh face (used only by the ``sim`` backends of camera and arm, and by tests).

- ``sim/render`` (``CaptureRequest``) → ``RGBDFrame`` from the camera pose the arm last reported, with the
  believed pose (profile errors) and the true one (ground truth).
- ``sim/joints`` (``JointState`` with true TCP/camera poses) → ``Ok``: the arm's sim driver streams set-points
  as requests, so they arrive in order and a move has reached the twin when the arm answers.
- ``sim/gripper`` (``GripperRequest``) → ``GripperResult``: closing at the current TCP grasps (or not, and
  why); opening sets a held object down with the profile's errors.
- ``sim/world`` (``Request``, ``params.op``): ``state``, ``reset`` (object, profile, seed), ``force_slip``,
  ``turn`` (by hand), ``gt_points`` (ground-truth surface samples in ``base``). Ground truth only.
"""

from __future__ import annotations

import asyncio

import numpy as np

from common import keys
from common.api import CaptureRequest, GripperRequest, GripperResult
from common.codec import Message
from common.errors import InvalidRequest
from common.messages import JointState, Ok, Request, RGBDFrame
from common.runtime import QueryContext, Service, run_service, service_arg_parser, settings_from_args
from services.sim.sensor_model import d435_intrinsics
from services.sim.world import World, default_object_pose


class SimService(Service):
    name = "sim"

    async def setup(self) -> None:
        opts = self.settings.options
        self.world = await self.run_cpu(World, opts.get("object", "milk"), profile=opts.get("profile", "ideal"),
                                        seed=int(opts.get("seed", 0)))
        self.seq = 0
        self.last_joints: JointState | None = None
        self._world_lock = asyncio.Lock()
        r = self.robot
        self.queryable(keys.sim(r, "render"), self.render)
        self.queryable(keys.sim(r, "joints"), self.joints)
        self.queryable(keys.sim(r, "gripper"), self.gripper)
        self.queryable(keys.sim(r, "world"), self.world_op)

    async def render(self, msg: Message | None, ctx: QueryContext) -> RGBDFrame:
        width = msg.width if isinstance(msg, CaptureRequest) and msg.width else 640
        height = msg.height if isinstance(msg, CaptureRequest) and msg.height else 480
        if (width, height) not in ((640, 480), (848, 480)):
            raise InvalidRequest("the twin renders the D435 presets 640x480 and 848x480",
                                 detail={"width": width, "height": height})
        self.seq += 1
        return await self.run_cpu(self.world.render_frame, None, d435_intrinsics(width, height), self.seq)

    async def joints(self, msg: Message | None, ctx: QueryContext) -> Ok:
        if not isinstance(msg, JointState):
            raise InvalidRequest("expected a JointState", detail={"got": type(msg).__name__})
        self.world.set_joint_state(msg.names, msg.position, T_base_gripper=msg.T_base_gripper,
                                   T_base_camera=msg.T_base_camera)
        self.last_joints = msg
        return Ok()

    async def gripper(self, msg: Message | None, ctx: QueryContext) -> GripperResult:
        if not isinstance(msg, GripperRequest):
            raise InvalidRequest("expected a GripperRequest", detail={"got": type(msg).__name__})
        w = self.world
        if msg.opening < w.gripper_opening - 1e-4 and not w.attached:
            if w.T_base_gripper is None:
                raise InvalidRequest("no TCP pose reported yet: move the arm before closing the gripper")
            outcome = await self.run_cpu(w.close_gripper, w.T_base_gripper, msg.opening)
            return GripperResult(opening=float(outcome.width), holding=bool(outcome.success), reason=outcome.reason)
        if w.attached and msg.opening <= w.gripper_opening + 1e-4:
            return GripperResult(opening=float(w.gripper_opening), holding=True, reason="already_holding")
        released = await self.run_cpu(w.open_gripper, msg.opening)
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
                obj = params.get("object", w.obj.name)
                profile = params.get("profile", w.profile.name)
                seed = int(params.get("seed", w.seed))
                pose = None
                if "x" in params or "y" in params or "yaw_deg" in params:
                    pose = default_object_pose(float(params.get("x", 0.6)), float(params.get("y", 0.0)),
                                               float(params.get("yaw_deg", 0.0)))
                self.world = await self.run_cpu(lambda: World(obj, profile=profile, seed=seed, object_pose=pose))
                self.seq = 0
                if self.last_joints is not None:  # the arm has not moved: the new world knows where it is
                    j = self.last_joints
                    self.world.set_joint_state(j.names, j.position, T_base_gripper=j.T_base_gripper,
                                               T_base_camera=j.T_base_camera)
            return Ok(info=self.world.state())
        if op == "force_slip":
            self.world.force_next_grasp_slip()
            return Ok(info={"armed": True})
        if op == "turn":
            achieved = self.world.turn_object(_number(params, "angle_deg", 30.0, -360.0, 360.0))
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

    def health_info(self) -> dict[str, object]:
        return {"object": self.world.obj.name, "profile": self.world.profile.name, "frames": self.seq}


def _number(params: dict, name: str, default: float, lo: float, hi: float) -> float:
    """A numeric request parameter, checked: a bad one is the caller's error, not the twin's."""
    value = params.get(name, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
        raise InvalidRequest(f"{name} must be a number in [{lo}, {hi}]", detail={name: repr(value)[:40]})
    return float(value)


def main() -> None:
    p = service_arg_parser("objscan digital twin (simulated table, object, arm, gripper and D435)")
    p.add_argument("--object", default="milk", help="HOPE object name or a mesh path (default: %(default)s)")
    p.add_argument("--profile", default="ideal", help="error profile: ideal | hand-turned | robot-turned")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    run_service(lambda: SimService(settings_from_args(args, object=args.object, profile=args.profile,
                                                      seed=args.seed)))
