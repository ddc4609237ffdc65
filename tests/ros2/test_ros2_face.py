"""The ROS 2 face on a real cell over Zenoh: twin, arm, camera, orchestrator and the face as processes on a loopback
router; this test is a plain Zenoh client that listens where a ``rmw_zenoh_cpp`` node would and decodes every
sample with rosbags' own CDR deserialiser and type store (an independent reader of what the face encoded).

Key expressions and liveliness tokens follow rmw_zenoh's ``docs/design.md`` (the literal examples are checked in
``test_rmw_formats.py``); here the face's real tokens, read from the router, are parsed with the same format.
"""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from common import keys
from common.api import ModelResult, ViewResult
from common.codec import decode
from common.launcher import ProcessSpec, ServiceGroup
from common.messages import JointState, Plane, PointCloud, Request, RGBDFrame
from services.calibration.file import HandEyeCalibration
from services.live.tap import tap_key, tap_message
from services.ros2 import rmw
from services.ros2.convert import transform_matrix
from services.ros2.types import TRIGGER, msg_class, serialize, type_hash

ROBOT = keys.DEFAULT_ROBOT
pytestmark = pytest.mark.slow  # a cell of real processes: a minute or more to start on 2 cores
TS = get_typestore(Stores.ROS2_JAZZY)  # the independent reader: rosbags' store as shipped...
# ... plus std_srvs/srv/Trigger's response, from the .srv text (the store holds messages only)
TS.register(get_types_from_msg("bool success\nstring message", "std_srvs/msg/Trigger_Response"))
# a calibrated mount the test chooses: 12 mm and a few degrees away from anything the twin would report
X = np.array([[0.0, -1.0, 0.0, 0.012], [1.0, 0.0, 0.0, -0.031], [0.0, 0.0, 1.0, 0.055], [0, 0, 0, 1.0]])
SCAN = {"object": "milk", "views": 2, "seed": 3}


def _key(name: str, ros_type: str) -> str:
    return rmw.topic_key(0, name, ros_type, type_hash(ros_type))


class Listener:
    """Every sample of some ROS 2 topics, with its attachment, as a rmw_zenoh subscription gets them."""

    def __init__(self, session, topics: dict[str, str]):  # noqa: ANN001
        self.samples: dict[str, list[tuple[bytes, bytes]]] = {t: [] for t in topics}
        self.lock = threading.Lock()
        self.subs = [session.declare_subscriber(_key(t, ty), self._on(t)) for t, ty in topics.items()]
        self.types = topics

    def _on(self, topic: str):  # noqa: ANN202
        def cb(sample) -> None:  # noqa: ANN001
            with self.lock:
                self.samples[topic].append((sample.payload.to_bytes(),
                                            sample.attachment.to_bytes() if sample.attachment else b""))
        return cb

    def decoded(self, topic: str) -> list:
        with self.lock:
            raw = list(self.samples[topic])
        return [TS.deserialize_cdr(p, self.types[topic]) for p, _ in raw]

    def wait(self, topic: str, n: int = 1, timeout: float = 30.0) -> list:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                if len(self.samples[topic]) >= n:
                    break
            time.sleep(0.05)
        got = self.decoded(topic)
        assert len(got) >= n, f"{topic}: {len(got)} samples after {timeout} s"
        return got

    def close(self) -> None:
        for s in self.subs:
            s.undeclare()


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ros2cell")
    calib = HandEyeCalibration(T_gripper_camera=X, T_gripper_camera_nominal=np.eye(4), info={"method": "test"})
    calib.save(tmp / "hand_eye.json")
    group = ServiceGroup(log_dir=tmp / "logs")
    group.start_router()
    try:
        group.launch([
            ProcessSpec("services.sim", [], service="sim"),
            ProcessSpec("services.arm", ["--backend", "sim"], service="arm"),
            ProcessSpec("services.camera", ["--backend", "sim"], service="camera"),
            ProcessSpec("services.orchestrator", ["--sessions", str(tmp / "sessions"), "--library", "", "--tap"],
                        service="orchestrator"),
            ProcessSpec("services.ros2", ["--hand-eye", str(tmp / "hand_eye.json"),
                                          "--scan-config", json.dumps(SCAN)], service="ros2"),
        ], timeout=120)
        yield group, tmp
    finally:
        group.stop_all()


def test_the_face_announces_its_node_topics_and_services_as_rmw_zenoh_does(cell):
    group, _ = cell
    tokens = [str(r.ok.key_expr) for r in group.session.liveliness().get("@ros2_lv/0/**", timeout=5.0) if r.ok]
    zid = tokens[0].split("/")[2] if tokens else ""
    assert f"@ros2_lv/0/{zid}/0/0/NN/%/%/objscan" in tokens
    pubs = {t.split("/")[9]: t for t in tokens if t.split("/")[5] == "MP"}
    assert set(pubs) == {"%joint_states", "%tf", "%tf_static", "%objscan%camera%color%image_raw",
                         "%objscan%camera%depth%image_rect_raw", "%objscan%camera%color%camera_info",
                         "%objscan%view_cloud", "%objscan%model", "%objscan%status"}
    parts = pubs["%joint_states"].split("/")
    assert parts[:9] == ["@ros2_lv", "0", zid, "0", parts[4], "MP", "%", "%", "objscan"]
    assert parts[10:] == ["sensor_msgs::msg::dds_::JointState_", TS.hash_rihs01("sensor_msgs/msg/JointState"),
                          "::,10:,:,:,,"]
    assert pubs["%tf_static"].endswith("/tf2_msgs::msg::dds_::TFMessage_/"
                                       + TS.hash_rihs01("tf2_msgs/msg/TFMessage") + "/:1:,1:,:,:,,")
    srvs = {t.split("/")[9]: t.split("/")[10:12] for t in tokens if t.split("/")[5] == "SS"}
    assert srvs == {n: ["std_srvs::srv::dds_::Trigger_", type_hash(TRIGGER)]
                    for n in ("%objscan%start_scan", "%objscan%stop_scan")}


def test_joint_states_and_tf_carry_the_arm_state_and_the_calibrated_camera(cell):
    group, _ = cell
    states: list[JointState] = []
    lock = threading.Lock()

    def on_state(sample) -> None:  # noqa: ANN001
        with lock:
            states.append(decode(sample.payload.to_bytes()))

    listener = Listener(group.session, {"/joint_states": "sensor_msgs/msg/JointState",
                                        "/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage"})
    sub = group.session.declare_subscriber(keys.arm(ROBOT, "state"), on_state)
    try:
        ros = listener.wait("/joint_states", 20)
        tf = [m for m in listener.wait("/tf", 20) if m.transforms[0].child_frame_id == "gripper"]
        with lock:
            by_stamp = {int(round(s.stamp * 1e9)): s for s in states}
        matched = 0
        for m in ros:
            s = by_stamp.get(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
            if s is None:
                continue
            matched += 1
            assert list(m.name) == list(s.names)
            np.testing.assert_array_equal(m.position, s.position)
        assert matched >= 10, f"only {matched} of {len(ros)} joint states matched an arm state"
        for m in tf:
            ts = m.transforms[0]
            s = by_stamp.get(ts.header.stamp.sec * 1_000_000_000 + ts.header.stamp.nanosec)
            if s is not None:
                assert ts.header.frame_id == "base"
                np.testing.assert_allclose(transform_matrix(ts), s.T_base_gripper, atol=1e-9)
    finally:
        sub.undeclare()
        listener.close()
    # /tf_static is transient local and was published when the face started: a late subscriber gets it from
    # the publisher's cache, as rmw_zenoh's transient-local subscription does
    got = _static_from_cache(group)
    ts = got[-1].transforms[0]
    assert (ts.header.frame_id, ts.child_frame_id) == ("gripper", "camera")
    np.testing.assert_allclose(transform_matrix(ts), X, atol=1e-9)
    s = states[-1]
    np.testing.assert_allclose(s.T_base_gripper @ transform_matrix(ts), s.T_base_gripper @ X, atol=1e-9)


def _static_from_cache(group: ServiceGroup) -> list:
    """What a late TRANSIENT_LOCAL subscriber of rmw_zenoh gets: the publisher's cached sample (advanced subscriber
    with history)."""
    import zenoh.ext as zext

    got: list = []
    done = threading.Event()

    def cb(sample) -> None:  # noqa: ANN001
        got.append(TS.deserialize_cdr(sample.payload.to_bytes(), "tf2_msgs/msg/TFMessage"))
        done.set()

    sub = zext.declare_advanced_subscriber(group.session, _key("/tf_static", "tf2_msgs/msg/TFMessage"), cb,
                                           history=zext.HistoryConfig(detect_late_publishers=True))
    try:
        done.wait(10.0)
    finally:
        sub.undeclare()
    return got


def cloud_arrays(msg) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """x y z and the packed rgb of a PointCloud2, read by its own field table (as RViz does)."""
    offs = {f.name: f.offset for f in msg.fields}
    data = np.asarray(msg.data, dtype=np.uint8).reshape(-1, msg.point_step)
    col = lambda name: data[:, offs[name]:offs[name] + 4].copy().view("<f4" if name != "rgb" else "<u4")[:, 0]  # noqa: E731
    packed = col("rgb")
    rgb = np.stack([(packed >> 16) & 255, (packed >> 8) & 255, packed & 255], axis=1).astype(np.uint8)
    return np.stack([col("x"), col("y"), col("z")], axis=1), rgb


def _call(session, name: str, seq: int) -> tuple[object, rmw.Attachment]:  # noqa: ANN001
    """A std_srvs/Trigger call as rmw_zenoh's client makes it: CDR request, attachment, a get on the service key."""
    gid = bytes(range(16))
    req = serialize(msg_class("std_srvs/srv/Trigger_Request")(), "std_srvs/srv/Trigger_Request")
    att = rmw.attachment(seq, time.time_ns(), gid)
    replies = list(session.get(_key(name, TRIGGER), payload=req, attachment=att, timeout=20.0))
    oks = [r.ok for r in replies if r.ok is not None]
    assert len(oks) == 1, [r.err for r in replies]
    reply_att = rmw.parse_attachment(oks[0].attachment.to_bytes())
    assert reply_att.sequence_number == seq and reply_att.gid == gid
    return TS.deserialize_cdr(oks[0].payload.to_bytes(), "std_srvs/msg/Trigger_Response"), reply_att


def test_a_scan_started_and_stopped_through_the_ros2_services_and_its_frames_on_ros2(cell):
    group, tmp = cell
    frames: list[RGBDFrame] = []

    def on_tap(sample) -> None:  # noqa: ANN001
        msg = decode(sample.payload.to_bytes())
        if isinstance(msg, Request) and isinstance(msg.params.get("reply"), RGBDFrame):
            frames.append(msg.params["reply"])

    tap = group.session.declare_subscriber(tap_key(ROBOT), on_tap)
    listener = Listener(group.session, {
        "/objscan/camera/color/image_raw": "sensor_msgs/msg/Image",
        "/objscan/camera/depth/image_rect_raw": "sensor_msgs/msg/Image",
        "/objscan/camera/color/camera_info": "sensor_msgs/msg/CameraInfo",
        "/objscan/status": "std_msgs/msg/String"})
    try:
        resp, _ = _call(group.session, "/objscan/start_scan", 7)
        assert resp.success, resp.message
        session_dir = Path(json.loads(resp.message)["session"])
        assert session_dir.parent == (tmp / "sessions").resolve()
        again, _ = _call(group.session, "/objscan/start_scan", 9)  # one acquisition at a time: a typed refusal
        assert not again.success and again.message.startswith("busy:"), again
        try:
            color = listener.wait("/objscan/camera/color/image_raw", 1, timeout=90)[0]
        except AssertionError as exc:  # say what the cell did meanwhile: the run's statuses, its services' logs
            raise AssertionError(f"{exc}; {len(frames)} frames on the tap; statuses "
                                 f"{[json.loads(m.data) for m in listener.decoded('/objscan/status')]}\n"
                                 + _log_tails(tmp / "logs")) from exc
        depth = listener.wait("/objscan/camera/depth/image_rect_raw", 1)[0]
        info = listener.wait("/objscan/camera/color/camera_info", 1)[0]
        resp, _ = _call(group.session, "/objscan/stop_scan", 8)
        assert resp.success, resp.message
        assert json.loads(resp.message)["stopped"] is True
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            statuses = [json.loads(m.data) for m in listener.decoded("/objscan/status")]
            if statuses and statuses[-1]["status"] == "stopped":
                break
            time.sleep(0.1)
        assert statuses[0]["status"] == "running" and statuses[-1]["status"] == "stopped", statuses
        journal = json.loads((session_dir / "journal.json").read_text())
        assert journal["status"] == "stopped"
    finally:
        tap.undeclare()
        listener.close()
    f = frames[0]
    h, w = f.depth.shape
    assert (color.height, color.width, color.encoding, color.step) == (h, w, "rgb8", 3 * w)
    np.testing.assert_array_equal(np.asarray(color.data).reshape(h, w, 3), f.color)
    assert (depth.encoding, depth.is_bigendian) == ("16UC1", 0)
    np.testing.assert_array_equal(np.frombuffer(np.asarray(depth.data).tobytes(), "<u2").reshape(h, w), f.depth)
    K = f.intrinsics
    np.testing.assert_allclose(info.k, [K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1])
    assert (info.width, info.height, info.header.frame_id) == (K.width, K.height, "camera")
    assert color.header.stamp.sec + color.header.stamp.nanosec * 1e-9 == pytest.approx(f.stamp, abs=1e-6)


def _log_tails(log_dir: Path, lines: int = 15) -> str:
    """The last lines of every service's log, for a failure message."""
    return "\n".join(f"--- {p.name}\n" + "\n".join(p.read_text(errors="replace").splitlines()[-lines:])
                     for p in sorted(log_dir.glob("*.log")))


def test_view_and_model_clouds_decode_to_their_points_and_colours(cell):
    """The tap's registration replies (as the orchestrator publishes them at the register and model steps)."""
    group, _ = cell
    rng = np.random.default_rng(5)
    model = PointCloud(xyz=rng.normal(size=(3000, 3)).astype(np.float32),
                       rgb=rng.integers(0, 256, (3000, 3), dtype=np.uint8))
    view = ViewResult(view=0, cloud=PointCloud(xyz=model.xyz[:500], rgb=model.rgb[:500]),
                      table=Plane(normal=np.array([0.0, 0, 1]), offset=0.0, center=np.array([0.6, 0, 0])),
                      center=np.array([0.6, 0.01, 0.07]), height=0.2, scan_poses=np.stack([np.eye(4)] * 3))
    listener = Listener(group.session, {"/objscan/model": "sensor_msgs/msg/PointCloud2",
                                        "/objscan/view_cloud": "sensor_msgs/msg/PointCloud2",
                                        "/tf": "tf2_msgs/msg/TFMessage"})
    pub = group.session.declare_publisher(tap_key(ROBOT))
    try:
        time.sleep(0.5)
        pub.put(tap_message(keys.REGISTRATION_STATIC, None, view, time.time(), time.time()).encode())
        pub.put(tap_message(keys.REGISTRATION_DYNAMIC, None, ModelResult(cloud=model), time.time(),
                            time.time()).encode())
        m = listener.wait("/objscan/model", 1)[0]
        v = listener.wait("/objscan/view_cloud", 1)[0]
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            obj = [x for x in listener.decoded("/tf") if x.transforms[0].child_frame_id == "object"]
            if obj:
                break
            time.sleep(0.05)
    finally:
        pub.undeclare()
        listener.close()
    assert m.header.frame_id == "base" and (m.height, m.width) == (1, 3000)
    assert [(f.name, f.offset, f.datatype) for f in m.fields] == [("x", 0, 7), ("y", 4, 7), ("z", 8, 7),
                                                                   ("rgb", 12, 7)]
    xyz, rgb = cloud_arrays(m)
    np.testing.assert_array_equal(xyz, model.xyz)
    np.testing.assert_array_equal(rgb, model.rgb)
    xyz, rgb = cloud_arrays(v)
    np.testing.assert_array_equal(xyz, model.xyz[:500])
    np.testing.assert_array_equal(rgb, model.rgb[:500])
    np.testing.assert_allclose(transform_matrix(obj[0].transforms[0])[:3, 3], view.center)
