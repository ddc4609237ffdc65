"""The ROS 2 face: the cell's state, frames, clouds and model as ROS 2 topics on rmw_zenoh keys, and scan start/stop
as ROS 2 services, on the same Zenoh router. No ROS installation is needed here: messages are CDR-encoded with
rosbags, keys and liveliness tokens spelled as ``rmw_zenoh_cpp`` spells them (``services/ros2/rmw.py``).

It subscribes to objscan's own keys and republishes:

| objscan key | ROS 2 topic (type) |
|---|---|
| ``objscan/{robot}/arm/state`` (50 Hz) | ``/joint_states`` (sensor_msgs/JointState), ``/tf`` base -> gripper |
| the tap: captures | ``/objscan/camera/color/image_raw``, ``.../depth/image_rect_raw``, ``.../camera_info`` |
| the tap: static registration replies | ``/objscan/view_cloud`` (sensor_msgs/PointCloud2), ``/tf`` base -> object |
| the tap: dynamic registration reply | ``/objscan/model`` (sensor_msgs/PointCloud2) |
| ``objscan/{robot}/orchestrator/status`` | ``/objscan/status`` (std_msgs/String, JSON) |
| hand-eye calibration file | ``/tf_static`` gripper -> camera (transient local) |

Services (std_srvs/Trigger): ``/objscan/start_scan`` sends ``orchestrator/run`` with the scan configuration the
face was started with; ``/objscan/stop_scan`` sends ``orchestrator/stop``. The orchestrator's own ACL applies:
the face calls its keys like any other client. The tap carries the scan's exchanges only when the
orchestrator publishes it (``--tap``, set by ``objscan up --ros2``, or a run started with ``live: true``).
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import zenoh

from common import keys
from common.codec import Message
from common.errors import ObjscanError
from common.geometry import invert
from common.log import event
from common.messages import JointState, Ok, Request
from common.runtime import Service, run_service, service_arg_parser, settings_from_args
from services.live.tap import tap_key
from services.ros2 import rmw, topics, types

log = logging.getLogger("objscan.ros2")

NODE = "objscan"

SERVICES: dict[str, str] = {"/objscan/start_scan": types.TRIGGER, "/objscan/stop_scan": types.TRIGGER}
SERVICE_QOS = rmw.QoS(depth=10)


@dataclass
class _Topic:
    name: str
    ros_type: str
    key: str
    token: str
    gid: bytes
    pub: Any
    seq: int = 0


class Ros2Face(Service):
    name = "ros2"

    async def setup(self) -> None:
        o = self.settings.options
        self.domain = int(o.get("domain_id", 0))
        self.distro = str(o.get("distro", types.DEFAULT_DISTRO))
        self.scan_config: dict[str, Any] = dict(o.get("scan_config") or {})
        self.sessions_prefix = str(o.get("session_prefix", "ros2"))
        self.hand_eye = o.get("hand_eye")  # HandEyeCalibration | None
        assert self.session is not None
        self.zid = str(self.session.zid())
        self.static_sent = False
        self.published: dict[str, int] = {}
        self._put_lock = threading.Lock()  # the loop and the executor both publish: one sequence per topic
        liveliness = self.session.liveliness()
        self._declared.append(liveliness.declare_token(rmw.node_token(self.domain, self.zid, 0, "/", NODE)))
        self.topics: dict[str, _Topic] = {}
        for i, (name, (ros_type, qos)) in enumerate(topics.TOPICS.items()):
            self.topics[name] = self._declare_topic(name, ros_type, qos, entity_id=10 + i)
        for j, (name, srv_type) in enumerate(SERVICES.items()):
            self._declare_service(name, srv_type, entity_id=100 + j)
        r = self.robot
        self.spawn(self._follow(tap_key(r), self._on_tap))
        self.spawn(self._follow(keys.arm(r, "state"), self._on_state, maxsize=64))
        self.spawn(self._follow(keys.orchestrator(r, "status"), self._on_status))
        if self.hand_eye is not None:
            await self._publish_static(self.hand_eye.T_gripper_camera, time.time(), "calibrated")

    def zenoh_config(self) -> zenoh.Config:
        """Timestamps on: a transient-local publisher's cache orders its samples by them (rmw_zenoh's sessions
        enable them too)."""
        conf = super().zenoh_config()
        conf.insert_json5("timestamping/enabled", '{"router": true, "peer": true, "client": true}')
        return conf

    # ------------------------------------------------------------------ declarations
    def _declare_topic(self, name: str, ros_type: str, qos: rmw.QoS, entity_id: int) -> _Topic:
        assert self.session is not None
        h = types.type_hash(ros_type, self.distro)
        key = rmw.topic_key(self.domain, name, ros_type, h)
        token = rmw.entity_token("MP", self.domain, self.zid, 0, entity_id, "/", NODE, name, ros_type, h, qos)
        if qos.durability == rmw.TRANSIENT_LOCAL:  # late joiners get the last sample (rmw_zenoh's cache)
            import zenoh.ext as zext

            pub = zext.declare_advanced_publisher(self.session, key, cache=zext.CacheConfig(qos.depth),
                                                  publisher_detection=True,
                                                  congestion_control=zenoh.CongestionControl.DROP)
        else:
            pub = self.session.declare_publisher(key, congestion_control=zenoh.CongestionControl.DROP)
        self._declared.append(pub)
        self._declared.append(self.session.liveliness().declare_token(token))
        return _Topic(name, ros_type, key, token, rmw.gid_of(token), pub)

    def _declare_service(self, name: str, srv_type: str, entity_id: int) -> None:
        assert self.session is not None and self.loop is not None
        h = types.type_hash(srv_type, self.distro)
        key = rmw.topic_key(self.domain, name, srv_type, h)
        token = rmw.entity_token("SS", self.domain, self.zid, 0, entity_id, "/", NODE, name, srv_type, h,
                                 SERVICE_QOS)
        loop = self.loop

        def on_query(query: zenoh.Query) -> None:  # zenoh thread: hand off only
            loop.call_soon_threadsafe(lambda: self.spawn(self._serve_trigger(name, query)))

        self._declared.append(self.session.declare_queryable(key, on_query, complete=True))
        self._declared.append(self.session.liveliness().declare_token(token))

    # ------------------------------------------------------------------ publishing
    def _put(self, name: str, msg: Any, t_ns: int | None = None) -> None:
        topic = self.topics[name]
        payload = types.serialize(msg, topic.ros_type, self.distro)
        with self._put_lock:
            topic.seq += 1
            att = rmw.attachment(topic.seq, t_ns if t_ns is not None else time.time_ns(), topic.gid)
            topic.pub.put(payload, attachment=att)
            self.published[name] = self.published.get(name, 0) + 1

    async def _put_cpu(self, items: list[tuple[str, Any]]) -> None:
        """Serialize and publish big messages (frames, clouds) off the event loop."""
        def work() -> None:
            for name, msg in items:
                self._put(name, msg)
        await self.run_cpu(work)

    async def _publish_static(self, T_gripper_camera: np.ndarray, t: float, source: str) -> None:
        self._put(*topics.static_camera(T_gripper_camera, t, self.distro))
        self.static_sent = True
        event(log, "tf_static published", source=source)

    # ------------------------------------------------------------------ objscan streams
    async def _follow(self, key: str, handler: Any, maxsize: int = 16) -> None:
        sub = self.subscribe(key, maxsize=maxsize)
        while True:
            _, msg = await sub.get()
            try:
                await handler(msg)
            except ObjscanError as exc:  # a message the face cannot show: say so, keep following
                event(log, "not republished", logging.WARNING, key=key, code=exc.code, error=exc.message)

    async def _on_state(self, msg: Message) -> None:
        if not isinstance(msg, JointState):
            return
        for name, ros in topics.of_state(msg, self.distro):
            self._put(name, ros)
        if not self.static_sent and msg.T_base_gripper is not None and msg.T_base_camera is not None:
            # no calibration file: the mount the arm reports (its URDF's)
            await self._publish_static(invert(msg.T_base_gripper) @ msg.T_base_camera, float(msg.stamp), "nominal")

    async def _on_status(self, msg: Message) -> None:
        for name, ros in topics.of_status(msg, self.distro):
            self._put(name, ros)

    async def _on_tap(self, msg: Message) -> None:
        if not isinstance(msg, Request):
            return
        p = msg.params
        t = float(p.get("t_received", time.time()))
        reply = p.get("reply")
        if reply is not None:
            # building the messages copies frames and clouds: off the loop, like their serialisation
            items = await self.run_cpu(topics.of_exchange, t, reply, self.distro)
            if items:
                await self._put_cpu(items)

    # ------------------------------------------------------------------ services
    async def _serve_trigger(self, name: str, query: zenoh.Query) -> None:
        """Answer one std_srvs/Trigger request: CDR response, the request's sequence number and client GID echoed."""
        try:
            try:
                req_att = rmw.parse_attachment(query.attachment.to_bytes()) if query.attachment else None
            except ValueError:
                req_att = None
            if req_att is None:
                event(log, "service request without an rmw attachment", logging.WARNING, service=name)
                return  # an rmw client always attaches one; without it no client could match the reply
            success, message = await self._trigger(name)
            resp = types.msg_class("std_srvs/srv/Trigger_Response", self.distro)(success=success, message=message)
            payload = types.serialize(resp, "std_srvs/srv/Trigger_Response", self.distro)
            att = rmw.attachment(req_att.sequence_number, time.time_ns(), req_att.gid)
            query.reply(query.key_expr, payload, attachment=att)
        except Exception as exc:
            event(log, "service reply failed", logging.ERROR, service=name, error=repr(exc))
        finally:
            query.drop()

    async def _trigger(self, name: str) -> tuple[bool, str]:
        r = self.robot
        try:
            if name == "/objscan/start_scan":
                out = f"{self.sessions_prefix}-{time.strftime('%Y%m%d-%H%M%S')}-{int(time.time_ns() % 1e6):06d}"
                reply = await self.request(keys.orchestrator(r, "run"),
                                           Request(params={"config": self.scan_config, "out": out}))
                info = reply.info if isinstance(reply, Ok) else {}
                return True, json.dumps({"session": info.get("session"), "status": info.get("status")})
            reply = await self.request(keys.orchestrator(r, "stop"), timeout=10.0)
            info = reply.info if isinstance(reply, Ok) else {}
            return bool(info.get("stopped")), json.dumps(info, default=str)
        except ObjscanError as exc:
            return False, f"{exc.code}: {exc.message}"

    def health_info(self) -> dict[str, object]:
        return {"domain_id": self.domain, "distro": self.distro, "published": dict(self.published)}


def main() -> None:
    from services.calibration.file import calibration_from_env

    p = service_arg_parser("objscan ros2: the cell as ROS 2 topics and services on rmw_zenoh keys")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS_DOMAIN_ID of the keys (default: $ROS_DOMAIN_ID or 0)")
    p.add_argument("--distro", choices=sorted(types.DISTROS), default=types.DEFAULT_DISTRO,
                   help="ROS 2 distribution whose message definitions and type hashes are used (default: %(default)s)")
    p.add_argument("--hand-eye", help="hand-eye calibration file for /tf_static (default: $OBJSCAN_HAND_EYE; "
                                      "without one, the mount the arm reports)")
    p.add_argument("--scan-config", default="{}",
                   help="JSON acquisition config that /objscan/start_scan starts (default: the orchestrator's)")
    args = p.parse_args()
    domain = args.domain_id if args.domain_id is not None else int(os.environ.get("ROS_DOMAIN_ID", "0") or 0)
    try:
        scan_config = json.loads(args.scan_config)
        if not isinstance(scan_config, dict):
            raise ValueError("not a JSON object")
    except ValueError as exc:
        raise SystemExit(f"--scan-config: {exc}") from None
    calibration, _ = calibration_from_env(args.hand_eye)
    run_service(lambda: Ros2Face(settings_from_args(args, domain_id=domain, distro=args.distro,
                                                    scan_config=scan_config, hand_eye=calibration)))

