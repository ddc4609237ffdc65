"""A session's recording as a ROS 2 bag: ``ros2 bag play OUT`` replays the scan into any ROS 2 graph.

The bag is a rosbag2 folder (``metadata.yaml`` and one MCAP file, rosbags' writer, format version 9) with the
topics of the live face (``services/ros2/topics.py``), ``ros2msg`` schemas and CDR messages. Every message is
stamped with the time the recording logged its source: an arm state or status sample when it arrived, a capture,
view or model when its reply arrived (exact nanoseconds, from the MCAP records). Header stamps are the sources'
own (a frame's capture stamp, a joint state's stamp). ``/tf_static`` holds one message, at the first state:
``gripper -> camera`` from the hand-eye file given, else the mount the arm reported (its URDF's).

Plain functions, no Zenoh: ``write_bag(session, out)`` is what ``objscan ros2-bag`` calls.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import StoragePlugin, Writer

from common.codec import decode
from common.errors import ObjscanError
from common.geometry import invert
from common.messages import JointState
from services.recording.reader import read_recording
from services.ros2 import rmw, topics, types
from services.ros2.errors import BagError

BAG_VERSION = 9
_INFINITE = QosTime(sec=9223372036, nsec=854775807)  # rmw's infinite duration


@dataclass
class BagSummary:
    path: Path
    counts: dict[str, int] = field(default_factory=dict)  # topic -> messages written
    skipped: int = 0  # recorded messages a topic shows that could not be decoded (a torn record): not in the bag
    distro: str = types.DEFAULT_DISTRO

    def as_dict(self) -> dict[str, Any]:
        return {"bag": str(self.path), "counts": dict(self.counts), "messages": sum(self.counts.values()),
                "skipped": self.skipped, "distro": self.distro}


def _qos(q: rmw.QoS) -> Qos:
    return Qos(history=QosHistory(q.history), depth=q.depth, reliability=QosReliability(q.reliability),
               durability=QosDurability(q.durability), deadline=_INFINITE, lifespan=_INFINITE,
               liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=_INFINITE,
               avoid_ros_namespace_conventions=False)


def bag_items(session: str | Path, distro: str = types.DEFAULT_DISTRO,
              T_gripper_camera: np.ndarray | None = None) -> tuple[list[tuple[int, str, Any]], int]:
    """(every ``(log time ns, topic, ROS 2 message)`` of a session's recording in time order, undecodable count)."""
    rec = read_recording(session)
    items: list[tuple[int, str, Any]] = []
    skipped = 0
    static_done = T_gripper_camera is not None
    for key, samples in rec.samples.items():
        is_state, is_status = key.endswith("/arm/state"), key.endswith("/orchestrator/status")
        if not (is_state or is_status):
            continue
        states: list[tuple[int, JointState]] = []
        for (_, payload), t_ns in zip(samples, rec.sample_ns.get(key, []), strict=True):
            try:
                msg = decode(payload)
            except ObjscanError:
                skipped += 1
                continue
            if is_state and isinstance(msg, JointState):
                states.append((t_ns, msg))
            elif is_status:
                items += [(t_ns, name, ros) for name, ros in topics.of_status(msg, distro)]
        for (t_ns, _), ros_items in zip(states, topics.of_states([m for _, m in states], distro), strict=True):
            items += [(t_ns, name, ros) for name, ros in ros_items]
        if not static_done:
            first = next((m for _, m in states if m.T_base_gripper is not None and m.T_base_camera is not None),
                         None)
            if first is not None:
                T_gripper_camera = invert(first.T_base_gripper) @ first.T_base_camera
                static_done = True
    for ex in rec.exchanges:
        if not ex.key.endswith(topics.EXCHANGE_KEY_ENDINGS):
            continue  # arm moves, grasp plans, pair jobs: nothing a topic shows
        try:
            reply = ex.reply_message()
        except ObjscanError:
            skipped += 1
            continue
        items += [(ex.t_received_ns, name, ros) for name, ros in topics.of_exchange(ex.t_received, reply, distro)]
    items.sort(key=lambda it: it[0])  # stable: a capture's image, depth and info stay in that order
    if T_gripper_camera is not None and items:
        t0 = items[0][0]
        name, ros = topics.static_camera(T_gripper_camera, t0 / 1e9, distro)
        items.insert(0, (t0, name, ros))
    return items, skipped


def write_bag(session: str | Path, out: str | Path, distro: str = types.DEFAULT_DISTRO,
              T_gripper_camera: np.ndarray | None = None) -> BagSummary:
    """Write the ROS 2 bag folder ``out`` (must not exist) from a session folder or ``.mcap`` recording."""
    dst = Path(out)
    if dst.exists():
        raise BagError(f"{dst} exists; a bag is never written over", detail={"path": str(dst)})
    items, skipped = bag_items(session, distro, T_gripper_camera)
    ts = types.typestore(distro)
    summary = BagSummary(path=dst, skipped=skipped, distro=distro)
    with Writer(dst, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {}
        for name, (ros_type, qos) in topics.TOPICS.items():
            if any(n == name for _, n, _ in items):
                conns[name] = writer.add_connection(name, ros_type, typestore=ts, serialization_format="cdr",
                                                    offered_qos_profiles=[_qos(qos)])
        for t_ns, name, ros in items:
            writer.write(conns[name], int(t_ns), types.serialize(ros, topics.TOPICS[name][0], distro))
            summary.counts[name] = summary.counts.get(name, 0) + 1
    return summary
