"""The arm service's Zenoh face.

- ``arm/move`` (``MoveRequest``) → ``MoveResult`` when the motion has finished (or a typed error: unreachable,
  colliding with the link pair named, outside the envelope, stopped); ``dry_run`` checks reachability only,
  and a dry ``pose``/``linear`` move may carry ``q``: the configuration to plan from instead of the arm's
  (checking a chain of moves before the first runs); a dry run's reply carries the configuration the motion
  would end in.
- ``arm/gripper`` (``GripperRequest``) → ``GripperResult`` (opening reached, holding something or not).
- ``arm/stop`` → halts any motion at once (handled on the event loop, never queued behind a move, a settle
  check or a state read) and holds every servo, the gripper included; ``Ok(estopped=True)`` only when the
  hold reached every servo, else an ``estop_failed`` error naming the servos (the stop stays latched as
  failed). ``Request(params={"reset": true})`` clears a latched stop.
- ``arm/scene`` (``SceneRequest``) → the object box the collision checker avoids.
- ``arm/state``: queryable and a ≥ 50 Hz ``JointState`` stream with TCP and camera poses, the e-stop state
  and the last fault. The bus is read in a thread of its own, one read at a time, and the stream never
  waits for it longer than one period (it publishes the last known state meanwhile), so a silent servo or
  a slow bus never holds the event loop that serves ``stop`` and health.
"""

from __future__ import annotations

import asyncio
import concurrent.futures

import numpy as np

from common import keys
from common.api import GripperRequest, GripperResult, MoveRequest, MoveResult, SceneRequest
from common.backend_options import option_pair
from common.codec import Message
from common.errors import InvalidRequest
from common.messages import JointState, Ok, Request
from common.runtime import COMMAND_BUDGET, QueryContext, Service, run_service, service_arg_parser, settings_from_args
from services.arm.arm import ArmConfig, ArmController
from services.arm.drivers.registry import BACKENDS, DriverContext, driver_entry, make_driver
from services.arm.kinematics import Kinematics

STATE_RATE_HZ = 50.0


class ArmService(Service):
    name = "arm"

    async def setup(self) -> None:
        opts = self.settings.options
        self.backend = opts.get("backend", "sim")
        entry = driver_entry(self.backend)
        entry.options(opts.get("backend_options") or {})  # a wrong key or value is said before anything starts
        config = ArmConfig(realtime=entry.realtime)
        kin = Kinematics(config.kinematics)
        driver, _ = make_driver(self.backend, DriverContext(self.session, self.robot, kin,
                                                            dict(opts.get("backend_options") or {})))
        self.arm = ArmController(driver, config, kinematics=kin)
        await self.run_cpu(self.arm.connect)
        # the state stream's bus reads: one thread, one read at a time, never on the event loop
        self._bus_reader = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="arm-state")
        self._refresh: asyncio.Future | None = None
        r = self.robot
        # commands are small: a hostile megabyte is refused unread; stop is never queued behind anything
        self.queryable(keys.arm(r, "move"), self.move, budget=COMMAND_BUDGET)
        self.queryable(keys.arm(r, "gripper"), self.gripper, budget=COMMAND_BUDGET)
        self.queryable(keys.arm(r, "stop"), self.stop_motion, budget=COMMAND_BUDGET, priority=True, inline=True)
        self.queryable(keys.arm(r, "scene"), self.scene, budget=COMMAND_BUDGET)
        self.queryable(keys.arm(r, "state"), self.state, budget=COMMAND_BUDGET)
        self.state_pub = self.publisher(keys.arm(r, "state"), block=False)
        self.spawn(self._stream_state())

    def _joint_state(self) -> JointState:
        """The last known state (no bus traffic: ``_refresh_bounded`` reads the bus off the loop)."""
        s = self.arm.state(read=False)
        return JointState(names=s["names"], position=np.asarray(s["q"], dtype=np.float64), stamp=s["stamp"],
                          T_base_gripper=s["T_base_gripper"], T_base_camera=s["T_base_camera"],
                          gripper_opening=s["gripper_opening"], moving=s["moving"], estop=s["estop"],
                          fault=s["fault"] or {})

    async def _refresh_bounded(self, timeout: float) -> None:
        """Read the bus in the reader thread, waiting at most ``timeout``; a read still running is not
        started twice (a slow read finishes in the background and the next tick uses it)."""
        assert self.loop is not None
        if self._refresh is None or self._refresh.done():
            self._refresh = self.loop.run_in_executor(self._bus_reader, self.arm.refresh)
        try:
            await asyncio.wait_for(asyncio.shield(self._refresh), timeout)
        except Exception:  # slow (TimeoutError) or failed: the state says the last known
            pass

    async def _stream_state(self) -> None:
        """Publish at ``STATE_RATE_HZ`` on a fixed schedule: each tick waits for the bus read only until the
        tick is due (re-anchored when the process was not scheduled for more than a period)."""
        assert self.loop is not None
        period = 1.0 / STATE_RATE_HZ
        due = self.loop.time()
        while True:
            due += period
            await self._refresh_bounded(max(0.0, due - self.loop.time()))
            try:
                self.state_pub.put(self._joint_state())
            except Exception:  # a publishing hiccup must not end the stream; the next tick retries
                pass
            delay = due - self.loop.time()
            if delay < -period:
                due = self.loop.time()
            await asyncio.sleep(max(0.0, delay))

    def _result(self, info: dict) -> MoveResult:
        s = self.arm.state(read=False)
        return MoveResult(q=np.asarray(s["q"], dtype=np.float64), T_base_gripper=s["T_base_gripper"],
                          T_base_camera=s["T_base_camera"], duration_s=float(info.get("duration_s", 0.0)),
                          info={k: v for k, v in info.items() if isinstance(v, (int, float, str, bool))})

    async def move(self, msg: Message | None, ctx: QueryContext) -> MoveResult:
        if not isinstance(msg, MoveRequest):
            raise InvalidRequest("expected a MoveRequest", detail={"got": type(msg).__name__})
        a = self.arm
        opening = msg.check_opening if msg.check_opening >= 0.0 else None
        if msg.kind == "joints":
            info = await self.run_cpu(a.move_joints, msg.q, msg.speed_scale, msg.dry_run)
        elif msg.kind == "home":
            info = await self.run_cpu(a.home, msg.speed_scale, msg.dry_run)
        elif msg.kind == "pose":
            info = await self.run_cpu(a.move_pose, msg.target, msg.speed_scale, msg.free_roll, msg.frame,
                                      msg.allow_object_contact, msg.dry_run, msg.q, opening)
        else:
            info = await self.run_cpu(a.move_linear, msg.target, msg.speed_scale, msg.frame,
                                      msg.allow_object_contact, msg.dry_run, msg.q, opening)
        if msg.dry_run:
            return self._planned_result(info)
        return self._result(info)

    def _planned_result(self, info: dict) -> MoveResult:
        """A dry run's reply: where the motion would end (nothing moved)."""
        q = np.asarray(info["q_end"], dtype=np.float64)
        frames = info["frames_end"]
        return MoveResult(q=q, T_base_gripper=frames["gripper"], T_base_camera=frames["camera"],
                          duration_s=float(info.get("duration_s", 0.0)),
                          info={k: v for k, v in info.items() if isinstance(v, (int, float, str, bool))})

    async def gripper(self, msg: Message | None, ctx: QueryContext) -> GripperResult:
        if not isinstance(msg, GripperRequest):
            raise InvalidRequest("expected a GripperRequest", detail={"got": type(msg).__name__})
        info = await self.run_cpu(self.arm.gripper, msg.opening, msg.force)
        last = getattr(self.arm.driver, "last_gripper", None)
        reason = last.reason if last is not None else ""
        return GripperResult(opening=float(info["opening"]), holding=bool(info["grasped"]), reason=reason)

    def stop_motion(self, msg: Message | None, ctx: QueryContext) -> Ok:
        """Inline (``common/runtime.py``): runs the moment the loop reaches the query, ahead of queued work."""
        if isinstance(msg, Request) and msg.params.get("reset"):
            self.arm.reset_estop()
            return Ok(info={"estopped": False})
        held = self.arm.estop()  # raises estop_failed (an Error reply naming the servos) when the hold failed
        info: dict = {"estopped": True}
        if "gripper_opening" in held:  # where the fingers were held (m)
            info["gripper_opening"] = float(held["gripper_opening"])
        return Ok(info=info)

    async def scene(self, msg: Message | None, ctx: QueryContext) -> Ok:
        if not isinstance(msg, SceneRequest):
            raise InvalidRequest("expected a SceneRequest", detail={"got": type(msg).__name__})
        # in the executor: the change waits for a motion check in progress (one lock, services/arm/collision.py),
        # and that wait must not hold the event loop (stop is answered there)
        if float(np.max(msg.extent)) <= 0.0:
            await self.run_cpu(self.arm.collision.clear_object)
        else:
            await self.run_cpu(self.arm.collision.set_object_box, msg.center, msg.extent, msg.yaw)
        return Ok(info={"object_box": bool(np.max(msg.extent) > 0)})

    async def state(self, msg: Message | None, ctx: QueryContext) -> JointState:
        await self._refresh_bounded(1.0 / STATE_RATE_HZ)
        return self._joint_state()

    async def teardown(self) -> None:
        if not hasattr(self, "arm"):  # the start failed before the driver was built: nothing to stop
            return
        try:
            self.arm.estop()
        except Exception:  # noqa: BLE001 - shutting down: the servos hold or relax per the shutdown policy
            pass
        await self.run_cpu(self.arm.close)
        self._bus_reader.shutdown(wait=False)

    def health_info(self) -> dict[str, object]:
        info: dict[str, object] = {"backend": self.backend, "estopped": self.arm.estopped,
                                   "estop": self.arm.estop_status}
        fault = self.arm.fault
        if fault:
            info["fault"] = fault
        servos = getattr(self.arm.driver, "servo_info", None)  # dynamixel: what answered at connect
        if servos:
            info["servos"] = {str(i): v["model"] for i, v in servos.items()}
        return info


def main() -> None:
    p = service_arg_parser("objscan arm service (PAPRAS: pinocchio IK, Ruckig motion, collision checks)")
    p.add_argument("--backend", choices=list(BACKENDS), default="sim",
                   help="arm driver (services/arm/drivers/registry.py; default: %(default)s)")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE", type=option_pair,
                   help="a backend's own option (repeatable; its keys: services/arm/drivers/registry.py, "
                        "docs/arm.md), e.g. dynamixel: --option port=/dev/ttyUSB0 --option emulate_bus=true")
    args = p.parse_args()
    run_service(lambda: ArmService(settings_from_args(args, backend=args.backend, backend_options=dict(args.option))))
