"""``objscan up --ros2`` on any ``--port`` starts the ROS 2 face beside the cell: its joint states arrive on the
rmw_zenoh key of that router, and without a calibration file ``/tf_static`` carries the mount the arm reports."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import zenoh.ext as zext
from rosbags.typesys import Stores, get_typestore

from common.launcher import free_tcp_port
from common.zenoh_config import ZenohSettings, open_session
from services.ros2 import rmw
from services.ros2.convert import transform_matrix
from services.ros2.types import type_hash

TS = get_typestore(Stores.ROS2_JAZZY)
pytestmark = pytest.mark.slow  # a cell of real processes: a minute or more to start on 2 cores


def _key(topic: str, ros_type: str) -> str:
    return rmw.topic_key(0, topic, ros_type, type_hash(ros_type))


def test_up_ros2_on_another_port_publishes_joint_states_and_the_reported_mount(tmp_path):
    port = free_tcp_port()
    proc = subprocess.Popen([sys.executable, "-m", "services.cli.main", "up", "--ros2", "--port", str(port),
                             "--only", "sim,arm", "--log-dir", str(tmp_path / "logs")],
                            env={**os.environ, "OMP_NUM_THREADS": "1"}, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    states: list = []
    static: list = []
    got = threading.Event()
    session = None
    try:
        deadline = time.monotonic() + 120
        while session is None and time.monotonic() < deadline:
            try:
                session = open_session(ZenohSettings(mode="client", connect=[f"tcp/127.0.0.1:{port}"]),
                                       connect_timeout=2.0)
            except Exception:
                assert proc.poll() is None, proc.stdout.read().decode() if proc.stdout else ""
                time.sleep(0.5)
        assert session is not None

        def on_state(sample) -> None:  # noqa: ANN001
            states.append(TS.deserialize_cdr(sample.payload.to_bytes(), "sensor_msgs/msg/JointState"))

        def on_static(sample) -> None:  # noqa: ANN001
            static.append(TS.deserialize_cdr(sample.payload.to_bytes(), "tf2_msgs/msg/TFMessage"))
            got.set()

        sub = session.declare_subscriber(_key("/joint_states", "sensor_msgs/msg/JointState"), on_state)
        adv = zext.declare_advanced_subscriber(session, _key("/tf_static", "tf2_msgs/msg/TFMessage"), on_static,
                                               history=zext.HistoryConfig(detect_late_publishers=True))
        while time.monotonic() < deadline and not (states and got.is_set()):
            assert proc.poll() is None, proc.stdout.read().decode() if proc.stdout else ""
            time.sleep(0.2)
        sub.undeclare()
        adv.undeclare()
        assert states, "no /joint_states from the ROS 2 face"
        assert len(states[-1].name) == len(states[-1].position) > 0
        assert static, "no /tf_static from the ROS 2 face"
        ts = static[-1].transforms[0]
        assert (ts.header.frame_id, ts.child_frame_id) == ("gripper", "camera")
        T = transform_matrix(ts)
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)
        assert 0.0 < np.linalg.norm(T[:3, 3]) < 0.3  # a wrist camera: centimetres from the flange
    finally:
        if session is not None:
            session.close()
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
