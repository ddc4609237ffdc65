"""A whole acquisition driven and watched from ROS 2 only: every service process plus the face, the scan started
with ``/objscan/start_scan``, the model taken from ``/objscan/model`` (decoded with rosbags) and compared with the
session's ``model.ply`` and the model reply the recording holds; then the session's ROS 2 bag counts against its
recording. Extended: a 3-view acquisition takes ~5 minutes on a shared 2-core box (CI skips it; ``-m extended``).
"""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from common.api import ModelResult
from common.launcher import ProcessSpec, ServiceGroup
from services.cell import cell_specs
from services.cli.main import main as objscan
from services.recording.reader import read_recording
from services.ros2 import rmw
from services.ros2.types import TRIGGER, msg_class, serialize, type_hash
from tests.conftest import shared_data

pytestmark = [pytest.mark.slow, pytest.mark.extended, pytest.mark.timeout(2400)]  # CI skips extended cases
TS = get_typestore(Stores.ROS2_JAZZY)
TS.register(get_types_from_msg("bool success\nstring message", "std_srvs/msg/Trigger_Response"))


def _key(name: str, ros_type: str) -> str:
    return rmw.topic_key(0, name, ros_type, type_hash(ros_type))


def test_a_scan_started_from_ros2_publishes_its_model_and_bags_its_recording(tmp_path):
    shared_data("hope", "milk")
    sessions = tmp_path / "sessions"
    group = ServiceGroup(log_dir=tmp_path / "logs")
    group.start_router()
    models: list = []
    statuses: list[dict] = []
    done = threading.Event()
    try:
        specs = cell_specs(extra_args={"orchestrator": ["--sessions", str(sessions), "--library", "", "--tap"]})
        specs.append(ProcessSpec("services.ros2", ["--scan-config", json.dumps({"object": "milk", "views": 3,
                                                                                "seed": 1})], service="ros2"))
        group.launch(specs, timeout=180)
        s = group.session

        def on_model(sample) -> None:  # noqa: ANN001
            models.append(TS.deserialize_cdr(sample.payload.to_bytes(), "sensor_msgs/msg/PointCloud2"))

        def on_status(sample) -> None:  # noqa: ANN001
            st = json.loads(TS.deserialize_cdr(sample.payload.to_bytes(), "std_msgs/msg/String").data)
            statuses.append(st)
            if st.get("status") in ("done", "failed", "stopped"):
                done.set()

        subs = [s.declare_subscriber(_key("/objscan/model", "sensor_msgs/msg/PointCloud2"), on_model),
                s.declare_subscriber(_key("/objscan/status", "std_msgs/msg/String"), on_status)]
        req = serialize(msg_class("std_srvs/srv/Trigger_Request")(), "std_srvs/srv/Trigger_Request")
        replies = [r.ok for r in s.get(_key("/objscan/start_scan", TRIGGER), payload=req,
                                       attachment=rmw.attachment(1, time.time_ns(), bytes(16)), timeout=30) if r.ok]
        resp = TS.deserialize_cdr(replies[0].payload.to_bytes(), "std_srvs/msg/Trigger_Response")
        assert resp.success, resp.message
        session = Path(json.loads(resp.message)["session"])
        assert done.wait(1500), statuses[-3:]
        deadline = time.monotonic() + 30
        while not models and time.monotonic() < deadline:
            time.sleep(0.2)
        for sub in subs:
            sub.undeclare()
    finally:
        group.stop_all()
    assert statuses[-1]["status"] == "done" and statuses[-1]["progress"] == 1.0, statuses[-1]
    assert len(models) == 1
    m = models[0]
    offs = {f.name: f.offset for f in m.fields}
    data = np.frombuffer(bytes(m.data), np.uint8).reshape(-1, m.point_step)
    xyz = np.stack([data[:, offs[c]:offs[c] + 4].copy().view("<f4")[:, 0] for c in "xyz"], axis=1)
    packed = data[:, offs["rgb"]:offs["rgb"] + 4].copy().view("<u4")[:, 0]
    rgb = np.stack([(packed >> 16) & 255, (packed >> 8) & 255, packed & 255], axis=1).astype(np.uint8)
    recorded = [ex.reply_message() for ex in read_recording(session).exchanges if ex.key.endswith("/dynamic")]
    model = next(r for r in recorded if isinstance(r, ModelResult)).cloud
    np.testing.assert_array_equal(xyz, model.xyz)
    np.testing.assert_array_equal(rgb, model.rgb)
    ply = o3d.io.read_point_cloud(str(session / "model.ply"))
    assert len(ply.points) == len(xyz)
    np.testing.assert_allclose(np.asarray(ply.points), xyz, atol=1e-6)

    out = tmp_path / "scan.bag"
    t0 = time.monotonic()
    assert objscan(["ros2-bag", str(session), "--out", str(out)]) == 0
    print(f"ros2-bag of a {len(xyz)}-point, 3-view session: {time.monotonic() - t0:.1f} s")
    rec = read_recording(session)
    with Reader(out) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        for conn, _t, raw in reader.messages():
            TS.deserialize_cdr(raw, conn.msgtype)  # every message decodes
    states = sum(len(v) for k, v in rec.samples.items() if k.endswith("/arm/state"))
    captures = sum(1 for ex in rec.exchanges if ex.key.endswith("/camera/capture") and
                   type(ex.reply_message()).__name__ == "RGBDFrame")
    assert counts["/joint_states"] == states and counts["/objscan/camera/color/image_raw"] == captures
    assert counts["/objscan/model"] == 1
