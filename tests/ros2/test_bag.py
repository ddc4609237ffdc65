"""A recorded session as a ROS 2 bag, read back by two independent readers: rosbags (its rosbag2 reader and CDR
deserialiser) and mcap-ros2-support (the MCAP library's ROS 2 decoder, which parses the ``ros2msg`` schemas stored
in the file, as ``ros2 bag`` and Foxglove do). Every message decodes; the counts and log times per topic equal
what the recording holds (read straight from its MCAP records, not through objscan's reader)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from common import keys
from common.api import ModelResult, ViewResult
from common.codec import decode
from common.geometry import invert
from common.messages import JointState, RGBDFrame
from services.cli.main import main as objscan
from services.recording.recorder import SessionRecorder
from tests.live.scan_messages import scan_items

R = keys.DEFAULT_ROBOT
EPOCH = 1_760_000_000.0


def _pose(x: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, 0.1, 0.4)
    T[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    return T


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    """A two-view session recorded by the orchestrator's own recorder: exchanges and 50 Hz joint states."""
    d = tmp_path_factory.mktemp("bag") / "milk-001"
    d.mkdir()
    rec = SessionRecorder(d / "session.mcap", {"session": {"object": "milk", "views": 2}})
    for kind, t, key, req, msg in scan_items():
        t += EPOCH
        if kind == "exchange":
            rec.tap(key, req, msg, t - 0.05, t + 0.000000123)
        elif isinstance(msg, JointState):
            for k in range(25):  # a burst of the arm's stream, with the poses a real arm reports
                s = JointState(names=list(msg.names), position=msg.position + 0.001 * k, stamp=t + 0.02 * k,
                               T_base_gripper=_pose(0.3 + 0.001 * k), T_base_camera=_pose(0.3 + 0.001 * k) @ _pose(0))
                rec.record_sample(keys.arm(R, "state"), s.encode(), t + 0.02 * k + 0.0004)
        else:
            rec.record_sample(keys.orchestrator(R, "status"), msg.encode(), t)
    rec.close()
    return d


def _expected(session: Path) -> tuple[dict[str, list[int]], dict]:
    """Topic -> log times (ns) the bag must hold, from the recording's raw records; and the source messages."""
    want: dict[str, list[int]] = {}
    src: dict[str, list] = {"state": [], "frame": [], "model": [], "view": []}

    def add(topic: str, t: int) -> None:
        want.setdefault(topic, []).append(t)

    with open(session / "session.mcap", "rb") as f:
        for _schema, channel, m in make_reader(f).iter_messages(log_time_order=True):
            kind, key = channel.metadata.get("kind"), channel.metadata.get("zenoh_key", "")
            if kind == "sample" and key.endswith("/arm/state"):
                add("/joint_states", m.log_time)
                add("/tf", m.log_time)
                src["state"].append(decode(m.data))
            elif kind == "sample" and key.endswith("/status"):
                add("/objscan/status", m.log_time)
            elif kind == "reply":
                reply = decode(m.data)
                if isinstance(reply, RGBDFrame):
                    for topic in ("/objscan/camera/color/image_raw", "/objscan/camera/depth/image_rect_raw",
                                  "/objscan/camera/color/camera_info"):
                        add(topic, m.log_time)
                    src["frame"].append(reply)
                elif isinstance(reply, ViewResult):
                    add("/objscan/view_cloud", m.log_time)
                    add("/tf", m.log_time)
                    src["view"].append(reply)
                elif isinstance(reply, ModelResult):
                    add("/objscan/model", m.log_time)
                    src["model"].append(reply)
    add("/tf_static", min(min(v) for v in want.values()))
    return {k: sorted(v) for k, v in want.items()}, src


def _cloud(msg) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """x y z and the packed rgb of a PointCloud2, located by its own field table."""
    offs = {f.name: f.offset for f in msg.fields}
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(-1, msg.point_step)
    def col(name: str, dt: str) -> np.ndarray:
        return data[:, offs[name]:offs[name] + 4].copy().view(dt)[:, 0]
    p = col("rgb", "<u4")
    return (np.stack([col("x", "<f4"), col("y", "<f4"), col("z", "<f4")], axis=1),
            np.stack([(p >> 16) & 255, (p >> 8) & 255, p & 255], axis=1).astype(np.uint8))


def test_the_bag_reads_back_with_rosbags_every_message_counts_and_times_equal(session, tmp_path):
    out = tmp_path / "milk-001.bag"
    assert objscan(["ros2-bag", str(session), "--out", str(out)]) == 0
    assert (out / "metadata.yaml").is_file() and list(out.glob("*.mcap"))
    want, src = _expected(session)
    ts = get_typestore(Stores.ROS2_JAZZY)
    got: dict[str, list[int]] = {}
    decoded: dict[str, list] = {}
    with Reader(out) as reader:
        assert reader.message_count == sum(len(v) for v in want.values())
        for conn, t, raw in reader.messages():
            got.setdefault(conn.topic, []).append(t)
            decoded.setdefault(conn.topic, []).append(ts.deserialize_cdr(raw, conn.msgtype))
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert {k: sorted(v) for k, v in got.items()} == want
    assert qos["/tf_static"][0].durability.name == "TRANSIENT_LOCAL"
    # content: the arm's state, the calibrated (here: reported) mount, frames and the model
    for m, s in zip(decoded["/joint_states"], src["state"], strict=True):
        assert list(m.name) == list(s.names)
        np.testing.assert_array_equal(m.position, s.position)
        assert m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 == pytest.approx(s.stamp, abs=1e-6)
    static = decoded["/tf_static"][0].transforms[0]
    s0 = src["state"][0]
    t = static.transform.translation
    np.testing.assert_allclose([t.x, t.y, t.z], (invert(s0.T_base_gripper) @ s0.T_base_camera)[:3, 3], atol=1e-12)
    for m, f in zip(decoded["/objscan/camera/color/image_raw"], src["frame"], strict=True):
        np.testing.assert_array_equal(np.asarray(m.data).reshape(f.color.shape), f.color)
    xyz, rgb = _cloud(decoded["/objscan/model"][0])
    np.testing.assert_array_equal(xyz, src["model"][0].cloud.xyz)
    np.testing.assert_array_equal(rgb, src["model"][0].cloud.rgb)


def test_the_bag_reads_back_with_mcap_ros2_support(session, tmp_path):
    out = tmp_path / "bag"
    assert objscan(["export", str(session), "--ros2-bag", str(out), "--json", "-"]) == 0
    want, src = _expected(session)
    got: dict[str, list[int]] = {}
    models = []
    with open(next(out.glob("*.mcap")), "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, ros in reader.iter_decoded_messages(log_time_order=True):
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            got.setdefault(channel.topic, []).append(message.log_time)
            if channel.topic == "/objscan/model":
                models.append(ros)
            if channel.topic == "/objscan/camera/color/camera_info":
                K = src["frame"][len(got[channel.topic]) - 1].intrinsics
                assert list(ros.k) == pytest.approx([K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1])
    assert {k: sorted(v) for k, v in got.items()} == want
    xyz, rgb = _cloud(models[0])
    np.testing.assert_array_equal(xyz, src["model"][0].cloud.xyz)
    np.testing.assert_array_equal(rgb, src["model"][0].cloud.rgb)


def test_a_bag_is_never_written_over_and_a_missing_recording_is_a_typed_error(session, tmp_path, capsys):
    out = tmp_path / "b"
    out.mkdir()
    assert objscan(["ros2-bag", str(session), "--out", str(out)]) == 1
    assert "bag_failed" in capsys.readouterr().err
    assert objscan(["ros2-bag", str(tmp_path / "nothing"), "--out", str(tmp_path / "c"), "--json"]) == 2  # bad input
    assert "[bad_recording]" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()
