"""rmw_zenoh's wire conventions, as plain functions: key expressions, liveliness tokens, QoS, attachments.

A ROS 2 system running ``rmw_zenoh_cpp`` on the same Zenoh router finds a publisher by its liveliness token
(``ros2 topic list``) and receives its samples on the topic's key expression; both must be spelled exactly as
rmw_zenoh spells them, or nothing matches. The formats (rmw_zenoh ``docs/design.md``, sections "Topic and
Service name mapping to Zenoh key expressions", "Graph Cache", "Publishers", "Service Servers"; and its
``liveliness_utils.cpp`` / ``qos.cpp`` / ``attachment_helpers.cpp``):

- data key: ``<domain_id>/<fully qualified name without the leading slash>/<DDS type name>/<type hash>``;
- liveliness token of a node: ``@ros2_lv/<domain>/<session id>/<node id>/<node id>/NN/<enclave>/<ns>/<node>``;
  of a publisher / service server: ``.../<entity id>/MP|SS/<enclave>/<ns>/<node>/<mangled name>/<type>/<hash>/<qos>``
  where a mangled name has every ``/`` replaced by ``%`` and an empty enclave or namespace is ``%``;
- QoS: ``reliability:durability:history,depth:deadline_s,ns:lifespan_s,ns:liveliness,lease_s,lease_ns``, each
  value left empty when it equals rmw_zenoh's default (reliable, volatile, keep-last 42, infinite durations,
  automatic liveliness);
- attachment of every sample, request and reply: sequence number (int64 LE), source timestamp (int64 LE, ns
  since the epoch), then the 16-byte GID with its one-byte length (16) in front.

Type names and hashes: ``pkg/msg/Name`` travels as ``pkg::msg::dds_::Name_``; the hash is REP-2016's RIHS01
(``services/ros2/types.py``); on Humble, which has no type hashes, rmw_zenoh writes ``TypeHashNotSupported``.
"""

from __future__ import annotations

import hashlib
import struct
from dataclasses import dataclass

ADMIN_SPACE = "@ros2_lv"
HUMBLE_TYPE_HASH = "TypeHashNotSupported"
GID_SIZE = 16

# rmw's enum values (rmw/types.h): reliability RELIABLE=1 BEST_EFFORT=2; durability TRANSIENT_LOCAL=1
# VOLATILE=2; history KEEP_LAST=1 KEEP_ALL=2
RELIABLE, BEST_EFFORT = 1, 2
TRANSIENT_LOCAL, VOLATILE = 1, 2
KEEP_LAST, KEEP_ALL = 1, 2
DEFAULT_DEPTH = 42  # rmw_zenoh's default history depth (qos.cpp)


@dataclass(frozen=True)
class QoS:
    """The QoS a publisher announces; only what differs from rmw_zenoh's defaults is written in its token."""

    reliability: int = RELIABLE
    durability: int = VOLATILE
    history: int = KEEP_LAST
    depth: int = 10

    def keyexpr(self) -> str:
        """The compact form rmw_zenoh puts in a liveliness token (``qos_to_keyexpr``)."""
        rel = "" if self.reliability == RELIABLE else str(self.reliability)
        dur = "" if self.durability == VOLATILE else str(self.durability)
        hist = "" if self.history == KEEP_LAST else str(self.history)
        depth = "" if self.depth == DEFAULT_DEPTH else str(self.depth)
        # deadline, lifespan and liveliness lease stay at their defaults (infinite, automatic)
        return f"{rel}:{dur}:{hist},{depth}:,:,:,,"


def mangle(name: str) -> str:
    """A ROS name as one key chunk: every ``/`` becomes ``%`` (an empty name is ``%``)."""
    return name.replace("/", "%") if name else "%"


def dds_type_name(ros_type: str) -> str:
    """``sensor_msgs/msg/Image`` -> ``sensor_msgs::msg::dds_::Image_`` (the name DDS and rmw_zenoh use)."""
    pkg, kind, name = ros_type.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def fully_qualified(name: str, namespace: str = "/") -> str:
    """A topic or service name as ROS resolves it: absolute names as they are, relative ones in the namespace."""
    if name.startswith("/"):
        return name
    ns = namespace.rstrip("/")
    return f"{ns}/{name}"


def topic_key(domain_id: int, name: str, ros_type: str, type_hash: str) -> str:
    """The data key expression of a topic or service (Zenoh keys never start with ``/``)."""
    return f"{domain_id}/{name.strip('/')}/{dds_type_name(ros_type)}/{type_hash}"


def node_token(domain_id: int, session_id: str, node_id: int, namespace: str, node: str, enclave: str = "") -> str:
    """The liveliness token that makes a node appear in ``ros2 node list``."""
    ns = "" if namespace == "/" else namespace
    return (f"{ADMIN_SPACE}/{domain_id}/{session_id}/{node_id}/{node_id}/NN/{mangle(enclave)}/{mangle(ns)}/"
            f"{node}")


def entity_token(kind: str, domain_id: int, session_id: str, node_id: int, entity_id: int, namespace: str,
                 node: str, name: str, ros_type: str, type_hash: str, qos: QoS, enclave: str = "") -> str:
    """The liveliness token of a publisher (``MP``), subscription (``MS``), service server (``SS``) or client
    (``SC``): what ``ros2 topic list`` / ``ros2 service list`` and the type checks of a subscriber read."""
    if kind not in ("MP", "MS", "SS", "SC"):
        raise ValueError(f"unknown entity kind {kind!r}")
    ns = "" if namespace == "/" else namespace
    return (f"{ADMIN_SPACE}/{domain_id}/{session_id}/{node_id}/{entity_id}/{kind}/{mangle(enclave)}/{mangle(ns)}/"
            f"{node}/{mangle(name)}/{dds_type_name(ros_type)}/{type_hash}/{qos.keyexpr()}")


def gid_of(token: str) -> bytes:
    """A 16-byte GID for an entity, derived from its liveliness token (unique per entity, stable).

    rmw_zenoh derives its own GIDs the same way but with XXH3-128; a GID only has to identify the sender
    (a subscriber reports it in ``MessageInfo``, a service echoes it to the client), so a SHA-256 prefix
    serves equally and needs no extra dependency."""
    return hashlib.sha256(token.encode()).digest()[:GID_SIZE]


def attachment(sequence_number: int, source_timestamp_ns: int, gid: bytes) -> bytes:
    """The attachment rmw_zenoh puts on every sample, request and reply."""
    if len(gid) != GID_SIZE:
        raise ValueError(f"a GID has {GID_SIZE} bytes, not {len(gid)}")
    return struct.pack("<qqB", int(sequence_number), int(source_timestamp_ns), GID_SIZE) + bytes(gid)


@dataclass(frozen=True)
class Attachment:
    sequence_number: int
    source_timestamp_ns: int
    gid: bytes


def parse_attachment(data: bytes) -> Attachment:
    """Read an rmw_zenoh attachment; ``ValueError`` when it is not one."""
    if len(data) != 17 + GID_SIZE or data[16] != GID_SIZE:
        raise ValueError(f"not an rmw_zenoh attachment ({len(data)} bytes)")
    seq, ts = struct.unpack_from("<qq", data, 0)
    return Attachment(seq, ts, bytes(data[17:17 + GID_SIZE]))
