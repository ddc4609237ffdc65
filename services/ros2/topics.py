"""Which objscan message becomes which ROS 2 message on which topic: one table, used live and for bags.

The face (``service.py``) feeds it the cell's streams as they arrive; the bag writer (``bag.py``) feeds it a
session's recording; both therefore publish the same topics with the same content.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from common.api import ModelResult, ViewResult
from common.codec import Message
from common.geometry import matrix_to_quat_xyzw
from common.messages import Error, JointState, Ok, RGBDFrame
from services.ros2 import convert, rmw

JOINT_STATES = "/joint_states"
TF = "/tf"
TF_STATIC = "/tf_static"
COLOR = "/objscan/camera/color/image_raw"
DEPTH = "/objscan/camera/depth/image_rect_raw"
CAMERA_INFO = "/objscan/camera/color/camera_info"
VIEW_CLOUD = "/objscan/view_cloud"
MODEL = "/objscan/model"
STATUS = "/objscan/status"

# topic -> (type, QoS): RELIABLE + KEEP_LAST as rmw_zenoh's publishers default to; TRANSIENT_LOCAL where a late
# subscriber needs the last message (the static transforms, the model)
TOPICS: dict[str, tuple[str, rmw.QoS]] = {
    JOINT_STATES: ("sensor_msgs/msg/JointState", rmw.QoS(depth=10)),
    TF: ("tf2_msgs/msg/TFMessage", rmw.QoS(depth=100)),
    TF_STATIC: ("tf2_msgs/msg/TFMessage", rmw.QoS(durability=rmw.TRANSIENT_LOCAL, depth=1)),
    COLOR: ("sensor_msgs/msg/Image", rmw.QoS(depth=5)),
    DEPTH: ("sensor_msgs/msg/Image", rmw.QoS(depth=5)),
    CAMERA_INFO: ("sensor_msgs/msg/CameraInfo", rmw.QoS(depth=5)),
    VIEW_CLOUD: ("sensor_msgs/msg/PointCloud2", rmw.QoS(depth=5)),
    MODEL: ("sensor_msgs/msg/PointCloud2", rmw.QoS(durability=rmw.TRANSIENT_LOCAL, depth=1)),
    STATUS: ("std_msgs/msg/String", rmw.QoS(depth=10)),
}


# the exchanges that carry something a topic shows (a capture, a view, the model): their keys end so
EXCHANGE_KEY_ENDINGS = ("/camera/capture", "registration/static", "registration/dynamic")


def of_exchange(t: float, reply: Message | None, distro: str) -> list[tuple[str, Any]]:
    """ROS 2 messages of one of the orchestrator's exchanges (a capture, a view, the model); others give none.

    ``t`` (seconds) stamps the clouds and the object transform; images carry their capture's own stamp."""
    if reply is None or isinstance(reply, Error):
        return []
    if isinstance(reply, RGBDFrame):
        ts = float(reply.stamp) or t
        return [(COLOR, convert.color_image(reply.color, ts, distro=distro)),
                (DEPTH, convert.depth_image(reply.depth, reply.depth_scale, ts, distro=distro)),
                (CAMERA_INFO, convert.camera_info(reply.intrinsics, ts, distro=distro))]
    if isinstance(reply, ViewResult):
        cloud = reply.cloud
        T = np.eye(4)
        T[:3, 3] = np.asarray(reply.center, dtype=np.float64)
        return [(VIEW_CLOUD, convert.point_cloud2(cloud.xyz, cloud.rgb, t, cloud.frame or convert.BASE, distro)),
                (TF, convert.tf_message([convert.transform_stamped(T, convert.BASE, convert.OBJECT, t, distro)],
                                        distro))]
    if isinstance(reply, ModelResult):
        cloud = reply.cloud
        return [(MODEL, convert.point_cloud2(cloud.xyz, cloud.rgb, t, cloud.frame or convert.BASE, distro))]
    return []


def of_state(msg: JointState, distro: str) -> list[tuple[str, Any]]:
    """``/joint_states`` and ``/tf`` base -> gripper of one arm state sample (stamped with its own stamp)."""
    return of_states([msg], distro)[0]


def of_states(msgs: list[JointState], distro: str) -> list[list[tuple[str, Any]]]:
    """``of_state`` of many samples, the gripper orientations converted in one call (a session has ~50 a second)."""
    posed = [m for m in msgs if m.T_base_gripper is not None]
    quats = (matrix_to_quat_xyzw(np.stack([np.asarray(m.T_base_gripper, dtype=np.float64)[:3, :3] for m in posed]))
             if posed else np.zeros((0, 4)))
    q_of = {id(m): q for m, q in zip(posed, quats, strict=True)}
    out = []
    for msg in msgs:
        t = float(msg.stamp)
        items = [(JOINT_STATES, convert.joint_state(msg.names, msg.position, t, msg.velocity, msg.effort, distro))]
        if msg.T_base_gripper is not None:
            p = np.asarray(msg.T_base_gripper, dtype=np.float64)[:3, 3]
            items.append((TF, convert.tf_message([convert.transform_stamped_pq(
                p, q_of[id(msg)], convert.BASE, convert.GRIPPER, t, distro)], distro)))
        out.append(items)
    return out


def of_status(msg: Message, distro: str) -> list[tuple[str, Any]]:
    if isinstance(msg, Ok) and "state" in msg.info:
        return [(STATUS, convert.status_text(dict(msg.info), distro))]
    return []


def static_camera(T_gripper_camera: np.ndarray, t: float, distro: str) -> tuple[str, Any]:
    """``/tf_static`` gripper -> camera: where the camera sits on the hand."""
    return TF_STATIC, convert.tf_message(
        [convert.transform_stamped(T_gripper_camera, convert.GRIPPER, convert.CAMERA, t, distro)], distro)
