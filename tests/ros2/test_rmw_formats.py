"""objscan spells keys, liveliness tokens, QoS, attachments and type hashes exactly as rmw_zenoh does.

Source of every literal below: ros2/rmw_zenoh, ``docs/design.md`` (rolling, 2025), sections "Topic and Service
name mapping to Zenoh key expressions" (the ``chatter`` / ``robot1`` / ``add_two_ints`` keys), "Graph Cache" (the
``listener`` / ``talker`` / ``add_two_ints_server`` tokens from demo_nodes_cpp) and "Publishers" / "Service
Servers" (the attachment layout: int64 sequence number, int64 timestamp, one length byte, 16 GID bytes, as
``attachment_helpers.cpp`` writes it with zenoh-ext's serializer).
"""

from __future__ import annotations

import zenoh.ext as zext
from rosbags.typesys import Stores, get_typestore

from services.ros2 import rmw, types

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
ADD_TWO_INTS_HASH = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"


def test_type_hashes_are_rosbags_rihs01_of_the_type_store_definitions():
    ts = get_typestore(Stores.ROS2_JAZZY)
    assert types.type_hash("std_msgs/msg/String") == ts.hash_rihs01("std_msgs/msg/String") == STRING_HASH
    for t in ("sensor_msgs/msg/JointState", "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo",
              "sensor_msgs/msg/PointCloud2", "tf2_msgs/msg/TFMessage"):
        assert types.type_hash(t) == ts.hash_rihs01(t)
    assert types.type_hash("std_msgs/msg/String", "humble") == "TypeHashNotSupported"


def test_a_service_hash_equals_rmw_zenohs_documented_add_two_ints():
    """A service is hashed as its request, response and event messages; the event's ServiceEventInfo carries
    ``client_gid`` as rosidl's IDL has it (``uint8[16]``): the same method then hashes std_srvs/Trigger."""
    ts = types.typestore("jazzy")
    types.register_service(ts, "example_interfaces/srv/AddTwoInts", "int64 a\nint64 b", "int64 sum")
    assert ts.hash_rihs01("example_interfaces/srv/AddTwoInts") == ADD_TWO_INTS_HASH
    assert types.type_hash(types.TRIGGER).startswith("RIHS01_")


def test_topic_and_service_keys_match_the_design_examples():
    assert rmw.topic_key(0, "chatter", "std_msgs/msg/String", STRING_HASH) == \
        "0/chatter/std_msgs::msg::dds_::String_/" + STRING_HASH
    assert rmw.topic_key(0, rmw.fully_qualified("chatter", "/robot1"), "std_msgs/msg/String", STRING_HASH) == \
        "0/robot1/chatter/std_msgs::msg::dds_::String_/" + STRING_HASH
    assert rmw.topic_key(2, "/add_two_ints", "example_interfaces/srv/AddTwoInts", ADD_TWO_INTS_HASH) == \
        "2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/" + ADD_TWO_INTS_HASH


def test_liveliness_tokens_match_the_design_examples():
    assert rmw.node_token(2, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "/", "listener") == \
        "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
    assert rmw.entity_token("MS", 2, "aac3178e146ba6f1fc6e6a4085e77f21", 0, 10, "/", "listener", "/chatter",
                            "std_msgs/msg/String", STRING_HASH, rmw.QoS(depth=10)) == \
        ("@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/"
         "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,10:,:,:,,")
    assert rmw.entity_token("MP", 2, "8b20917502ee955ac4476e0266340d5c", 0, 10, "/", "talker", "/chatter",
                            "std_msgs/msg/String", STRING_HASH, rmw.QoS(depth=7)) == \
        ("@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/"
         "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,7:,:,:,,")
    assert rmw.entity_token("SS", 2, "f9980ee0495eaafb3e38f0d19e2eae12", 0, 10, "/", "add_two_ints_server",
                            "/add_two_ints", "example_interfaces/srv/AddTwoInts", ADD_TWO_INTS_HASH,
                            rmw.QoS(depth=10)) == \
        ("@ros2_lv/2/f9980ee0495eaafb3e38f0d19e2eae12/0/10/SS/%/%/add_two_ints_server/%add_two_ints/"
         "example_interfaces::srv::dds_::AddTwoInts_/"
         "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a/::,10:,:,:,,")


def test_qos_differs_from_the_defaults_only_where_it_must():
    assert rmw.QoS(depth=42).keyexpr() == "::,:,:,:,,"  # every default: nothing written
    assert rmw.QoS(durability=rmw.TRANSIENT_LOCAL, depth=1).keyexpr() == ":1:,1:,:,:,,"
    assert rmw.QoS(reliability=rmw.BEST_EFFORT, history=rmw.KEEP_ALL, depth=42).keyexpr() == "2::2,:,:,:,,"


def test_the_attachment_is_zenoh_ext_serialization_of_seq_timestamp_gid():
    gid = bytes(range(16))
    ours = rmw.attachment(7, 1_760_000_000_123_456_789, gid)
    theirs = zext.z_serialize((zext.Int64(7), zext.Int64(1_760_000_000_123_456_789), gid)).to_bytes()
    assert ours == theirs and len(ours) == 8 + 8 + 1 + 16
    a = rmw.parse_attachment(ours)
    assert (a.sequence_number, a.source_timestamp_ns, a.gid) == (7, 1_760_000_000_123_456_789, gid)
