"""Serves scene events over the Foxglove WebSocket protocol (``--foxglove``): open Foxglove, connect to
``ws://HOST:PORT``.

Topics and schemas are those of a recording's visual channels (``services/recording/visual.py`` builds
the protobuf messages for both), so a live cell, a replay and a recorded ``.mcap`` look the same:
``/camera/color``, ``/camera/depth``, ``/camera/calibration``, ``/camera/capture_pose``, ``/tf`` (the URDF
links' joint transforms, ``base`` = the URDF root), ``/arm/joints``, ``/views/NN/object``,
``/locate/object``, ``/grasps``, ``/grasps/chosen``, ``/model_preview`` (the growing model),
``/model`` and ``/status`` (``foxglove.Log``).
Each sink has its own ``foxglove.Context``, so two sinks in one process never share channels.
"""

from __future__ import annotations

import time

import foxglove
import foxglove.messages as fm
import numpy as np

from common.messages import PointCloud
from services.live import scene
from services.live.urdf_joints import UrdfJoint, joint_transforms, load_joints
from services.recording import visual

URDF_ROOT_FRAME = "world"


def _ns(t: float) -> int:
    return max(0, int(round(float(t) * 1e9)))


class FoxgloveSink:
    """A Foxglove WebSocket server on ``host:port`` (port 0: any free one, see ``.port``)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, *, name: str = "objscan"):
        self.context = foxglove.Context()
        self.server = foxglove.start_server(name=name, host=host, port=port, context=self.context)
        self.port = int(self.server.port)
        self.joints: list[UrdfJoint] = load_joints()
        self._channels: dict[str, foxglove.Channel] = {}

    def _log(self, t: float, visuals: list[visual.Visual]) -> None:
        for topic, schema_name, data in visuals:
            ch = self._channels.get(topic)
            if ch is None:
                encoding, schema_data = visual.schema(schema_name)
                ch = foxglove.Channel(topic, schema=foxglove.Schema(name=schema_name, encoding=encoding,
                                                                    data=schema_data),
                                      message_encoding="protobuf", context=self.context)
                self._channels[topic] = ch
            ch.log(data, log_time=_ns(t))

    def _tf(self, t: float, names: list[str], q: np.ndarray) -> visual.Visual:
        transforms = [visual.frame_transform(t, j.parent, j.child, T)
                      for j, T in joint_transforms(self.joints, names, q, include_fixed=True)]
        # ``base`` (objscan's frame) is the URDF root; the camera and gripper frames already hang off base
        transforms.append(visual.frame_transform(t, visual.BASE, URDF_ROOT_FRAME, np.eye(4)))
        return ("/tf", "foxglove.FrameTransforms", fm.FrameTransforms(transforms=transforms).encode())

    def handle(self, event: scene.Event) -> None:
        t = event.t
        out: list[visual.Visual] = []
        if isinstance(event, scene.CameraFrame):
            out += visual.rgbd(t, event.frame)
        elif isinstance(event, scene.ArmState):
            out.append(self._tf(t, event.names, event.q))
            joints = [fm.JointState(name=n, position=float(p)) for n, p in zip(event.names, event.q, strict=False)]
            out.append(("/arm/joints", "foxglove.JointStates",
                        fm.JointStates(timestamp=visual.stamp(t), joints=joints).encode()))
        elif isinstance(event, scene.ViewCloud):
            topic = "/locate/object" if event.view < 0 else f"/views/{event.view:02d}/object"
            out.append((topic, "foxglove.PointCloud", visual.point_cloud(t, event.cloud)))
        elif isinstance(event, scene.GraspCandidates):
            poses = [visual.pose_msg(P) for P in event.poses]
            out.append(("/grasps", "foxglove.PosesInFrame",
                        fm.PosesInFrame(timestamp=visual.stamp(t), frame_id=visual.BASE, poses=poses).encode()))
        elif isinstance(event, scene.ChosenGrasp):
            out.append(("/grasps/chosen", "foxglove.PoseInFrame",
                        fm.PoseInFrame(timestamp=visual.stamp(t), frame_id=visual.BASE,
                                       pose=visual.pose_msg(event.pose)).encode()))
        elif isinstance(event, scene.ModelPreview):
            out.append(("/model_preview", "foxglove.PointCloud",
                        visual.point_cloud(t, PointCloud(xyz=event.xyz, rgb=event.rgb))))
        elif isinstance(event, scene.Model):
            out.append(("/model", "foxglove.PointCloud", visual.point_cloud(t, event.cloud)))
        elif isinstance(event, scene.Status):
            s = event.info
            text = f"view {s.get('view')}: {s.get('state')} ({s.get('views_done', 0)}/{s.get('views')} views)"
            out.append(("/status", "foxglove.Log", fm.Log(timestamp=visual.stamp(t), level=fm.LogLevel.Info,
                                                          message=text, name="orchestrator").encode()))
        self._log(t, out)

    def close(self, linger_s: float = 0.0) -> None:
        """Stop serving (after ``linger_s`` so a client can take the last messages)."""
        if linger_s > 0:
            time.sleep(linger_s)
        self.server.stop()
