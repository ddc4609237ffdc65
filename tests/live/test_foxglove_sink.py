"""The Foxglove sink as Foxglove sees it: a WebSocket client on loopback gets the channels and the messages.

The client speaks the Foxglove WebSocket protocol (subprotocol ``foxglove.sdk.v1`` in foxglove-sdk 0.30):
it reads the server's ``advertise``, subscribes to every channel, and decodes the binary message frames
with the advertised protobuf schemas, so the test fails if a channel, a schema or a payload is wrong.
"""

from __future__ import annotations

import base64
import json
import struct
import threading
import time

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from services.live.feed import LiveView
from services.live.foxglove_sink import FoxgloveSink
from tests.live.scan_messages import feed, scan_items

websockets_sync = pytest.importorskip("websockets.sync.client")

EXPECTED = {"/camera/color", "/camera/depth", "/camera/calibration", "/camera/capture_pose", "/tf", "/arm/joints",
            "/views/00/object", "/views/01/object", "/grasps", "/grasps/chosen", "/model", "/model_preview", "/status"}


def _message_class(schema_name: str, schema_b64: str):  # noqa: ANN202
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(schema_b64))
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


def _advertised(ws, wanted: set[str], timeout: float = 10.0) -> dict[str, dict]:  # noqa: ANN001
    channels: dict[str, dict] = {}
    deadline = time.monotonic() + timeout
    while not wanted <= set(channels) and time.monotonic() < deadline:
        msg = ws.recv(timeout=max(0.1, deadline - time.monotonic()))
        if isinstance(msg, str):
            doc = json.loads(msg)
            if doc.get("op") == "advertise":
                channels.update({c["topic"]: c for c in doc["channels"]})
    return channels


def test_a_client_sees_every_channel_and_decodes_the_messages():
    sink = FoxgloveSink(port=0)
    view = LiveView([sink])
    try:
        feed(view, scan_items())  # channels exist once something was logged on them
        with websockets_sync.connect(f"ws://127.0.0.1:{sink.port}", subprotocols=["foxglove.sdk.v1"],
                                     open_timeout=10) as ws:
            channels = _advertised(ws, EXPECTED)
            assert set(channels) >= EXPECTED, EXPECTED - set(channels)
            assert channels["/model"]["schemaName"] == "foxglove.PointCloud"
            assert channels["/tf"]["schemaName"] == "foxglove.FrameTransforms"
            assert all(c["encoding"] == "protobuf" for c in channels.values())
            subs = {i + 1: topic for i, topic in enumerate(sorted(channels))}
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": sid, "channelId": channels[topic]["id"]} for sid, topic in subs.items()]}))
            time.sleep(0.5)  # the server applies the subscription before the next messages
            threading.Thread(target=feed, args=(view, scan_items()), daemon=True).start()
            got: dict[str, list] = {}
            deadline = time.monotonic() + 20
            while "/model" not in got and time.monotonic() < deadline:
                msg = ws.recv(timeout=max(0.1, deadline - time.monotonic()))
                if isinstance(msg, bytes) and msg[0] == 0x01:  # MessageData: op, sub id, log time, payload
                    sid, _ = struct.unpack_from("<IQ", msg, 1)
                    topic = subs[sid]
                    cls = _message_class(channels[topic]["schemaName"], channels[topic]["schema"])
                    got.setdefault(topic, []).append(cls.FromString(msg[13:]))
    finally:
        view.close()
    model = got["/model"][0]
    assert model.point_stride == 16 and len(model.data) == 500 * 16 and model.frame_id == "base"
    xyz = np.frombuffer(model.data, dtype=[("xyz", "<f4", 3), ("rgba", "u1", 4)])["xyz"]
    assert np.isfinite(xyz).all() and abs(float(xyz[:, 0].mean()) - 0.4) < 0.02  # the cloud around x = 0.4 m
    depth = got["/camera/depth"][0]
    assert (depth.width, depth.height, depth.encoding) == (64, 48, "16UC1")
    tf = got["/tf"][-1]
    children = {t.child_frame_id for t in tf.transforms}
    assert {"robot1/link2", "robot1/link6", "gripper", "camera", "world"} <= children
    chosen = got["/grasps/chosen"][0].pose.position
    assert (chosen.x, chosen.y, chosen.z) == pytest.approx((0.4, 0.0, 0.06))
    assert len(got["/grasps"][0].poses) == 2
