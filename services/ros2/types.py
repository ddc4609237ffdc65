"""ROS 2 message types without ROS: rosbags' type stores (Humble, Jazzy), CDR, and RIHS01 type hashes.

The message types come from rosbags' stores, which carry the distributions' own definitions. Two things are
added here:

- ``std_srvs/srv/Trigger`` (the stores hold messages, not services): its request, response and event
  messages as rosidl generates them, and the service itself as the three-field type REP-2016 hashes
  (``request_message``, ``response_message``, ``event_message``);
- for that hash, ``service_msgs/msg/ServiceEventInfo.client_gid`` as ``uint8[16]``: the ``.msg`` says
  ``char[16]``, which rosidl turns into ``uint8`` before hashing, while the store keeps ``char``. With this the
  hash of ``example_interfaces/srv/AddTwoInts`` equals the literal in rmw_zenoh's design document (tested).

Message hashes are the store's own ``hash_rihs01``; on Humble (no type hashes) rmw_zenoh writes
``TypeHashNotSupported`` instead.
"""

from __future__ import annotations

from functools import cache
from typing import Any

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Nodetype, Typestore

from services.ros2.rmw import HUMBLE_TYPE_HASH

DISTROS = {"jazzy": Stores.ROS2_JAZZY, "humble": Stores.ROS2_HUMBLE}
DEFAULT_DISTRO = "jazzy"

TRIGGER = "std_srvs/srv/Trigger"


def _srv_types(srv: str, request: str, response: str, with_event: bool) -> dict[str, Any]:
    """The messages rosidl makes of a ``.srv`` (``X_Request``, ``X_Response``, on Iron+ ``X_Event``), and the
    service as a three-field type for its hash; rosbags' parser files them under ``pkg/srv/msg/``, renamed here."""
    pkg = srv.split("/")[0]
    types: dict[str, Any] = {}
    types.update(get_types_from_msg(request, f"{srv}_Request"))
    types.update(get_types_from_msg(response, f"{srv}_Response"))
    if with_event:
        types.update(get_types_from_msg(
            f"service_msgs/ServiceEventInfo info\n{srv}_Request[<=1] request\n{srv}_Response[<=1] response",
            f"{srv}_Event"))
        types.update(get_types_from_msg(
            f"{srv}_Request request_message\n{srv}_Response response_message\n{srv}_Event event_message", srv))

    def ren(x: Any) -> Any:
        if isinstance(x, str):
            return x.replace(f"{pkg}/srv/msg/", f"{pkg}/srv/")
        if isinstance(x, (tuple, list)):
            return type(x)(ren(i) for i in x)
        return x

    return {ren(k): ren(v) for k, v in types.items()}


@cache
def typestore(distro: str = DEFAULT_DISTRO) -> Typestore:
    """The type store of a distribution, with the services objscan offers registered."""
    if distro not in DISTROS:
        raise ValueError(f"unknown ROS 2 distribution {distro!r}; choose one of {sorted(DISTROS)}")
    ts = get_typestore(DISTROS[distro])
    with_event = "service_msgs/msg/ServiceEventInfo" in ts.fielddefs
    if with_event:
        consts, fields = ts.fielddefs["service_msgs/msg/ServiceEventInfo"]
        ts.fielddefs["service_msgs/msg/ServiceEventInfo"] = (consts, [
            (n, (Nodetype.ARRAY, ((Nodetype.BASE, ("uint8", 0)), 16))) if n == "client_gid" else (n, d)
            for n, d in fields])
    ts.register(_srv_types(TRIGGER, "", "bool success\nstring message", with_event))
    return ts


def register_service(ts: Typestore, srv: str, request: str, response: str) -> None:
    """Register another service's types in ``ts`` (tests check the hash method on a documented service)."""
    ts.register(_srv_types(srv, request, response, "service_msgs/msg/ServiceEventInfo" in ts.fielddefs))


@cache
def type_hash(ros_type: str, distro: str = DEFAULT_DISTRO) -> str:
    """RIHS01 hash of a message or service type as rmw_zenoh puts it in keys (Humble: the placeholder)."""
    if distro == "humble":
        return HUMBLE_TYPE_HASH
    return typestore(distro).hash_rihs01(ros_type)


def serialize(msg: Any, ros_type: str, distro: str = DEFAULT_DISTRO) -> bytes:
    """CDR bytes (little-endian, with the 4-byte encapsulation header) of a message."""
    return bytes(typestore(distro).serialize_cdr(msg, ros_type))


def deserialize(data: bytes, ros_type: str, distro: str = DEFAULT_DISTRO) -> Any:
    return typestore(distro).deserialize_cdr(data, ros_type)


def msg_class(ros_type: str, distro: str = DEFAULT_DISTRO) -> Any:
    """The generated dataclass of a type, to build messages with."""
    return typestore(distro).types[ros_type]
