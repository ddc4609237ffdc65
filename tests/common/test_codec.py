"""Wire codec: every message type round-trips; every malformed-input class gives a typed error."""

from __future__ import annotations

import dataclasses

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from common.codec import MAX_PAYLOAD_BYTES, decode, encode, registered_types
from common.errors import WireError
from common.geometry import make_transform, rotation_about_axis
from common.messages import (
    Error,
    Grasp,
    Health,
    Intrinsics,
    JointState,
    Ok,
    Plane,
    PointCloud,
    Pose,
    Request,
    RGBDFrame,
    Transform,
)

finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False, width=32)
unit_quats = st.tuples(*[st.floats(-1, 1) for _ in range(4)]).filter(lambda q: np.linalg.norm(q) > 0.1).map(
    lambda q: np.asarray(q) / np.linalg.norm(q))
small_text = st.text(max_size=12)
json_leaf = st.one_of(st.none(), st.booleans(), st.integers(-2**40, 2**40), finite, small_text)
json_like = st.recursive(json_leaf, lambda c: st.one_of(st.lists(c, max_size=4),
                                                        st.dictionaries(small_text, c, max_size=4)), max_leaves=12)


def arrays(dtype, shape, elements=None):  # noqa: ANN001, ANN201
    return hnp.arrays(dtype, shape, elements=elements if elements is not None else
                      (finite if np.dtype(dtype).kind == "f" else None))


@st.composite
def rgbd_frames(draw):  # noqa: ANN001, ANN201
    h, w = draw(st.integers(1, 12)), draw(st.integers(1, 12))
    return RGBDFrame(color=draw(arrays(np.uint8, (h, w, 3))), depth=draw(arrays(np.uint16, (h, w))),
                     depth_scale=draw(st.floats(1e-5, 1.0)),
                     intrinsics=Intrinsics(width=w, height=h, fx=draw(st.floats(1, 2000)), fy=500.0, cx=1.0, cy=2.0),
                     T_base_camera=make_transform(rotation_about_axis([0, 0, 1], draw(st.floats(-3, 3))), [1, 2, 3]),
                     stamp=draw(st.floats(0, 1e9)), seq=draw(st.integers(0, 2**31)),
                     T_base_camera_true=draw(st.none() | st.just(np.eye(4))),
                     meta=draw(st.dictionaries(small_text, json_like, max_size=3)))


@st.composite
def clouds(draw):  # noqa: ANN001, ANN201
    n = draw(st.integers(0, 50))
    return PointCloud(xyz=draw(arrays(np.float32, (n, 3))),
                      rgb=draw(st.none() | arrays(np.uint8, (n, 3))),
                      normals=draw(st.none() | arrays(np.float32, (n, 3))), frame=draw(small_text))


STRATEGIES = {
    "Intrinsics": st.builds(Intrinsics, width=st.integers(1, 5000), height=st.integers(1, 5000),
                            fx=st.floats(0.1, 5000), fy=st.floats(0.1, 5000), cx=finite, cy=finite),
    "RGBDFrame": rgbd_frames(),
    "PointCloud": clouds(),
    "Pose": st.builds(Pose, position=arrays(np.float64, (3,)), orientation=unit_quats, frame=small_text),
    "Transform": st.builds(lambda a, t: Transform(matrix=make_transform(rotation_about_axis([1, 2, 3], a), t),
                                                  parent="base", child="camera"),
                           st.floats(-3, 3), arrays(np.float64, (3,))),
    "JointState": st.integers(0, 7).flatmap(lambda n: st.builds(
        JointState, names=st.lists(small_text, min_size=n, max_size=n), position=arrays(np.float64, (n,)),
        velocity=st.none() | arrays(np.float64, (n,)), stamp=st.floats(0, 1e9), moving=st.booleans())),
    # a unit quaternion's first three components can all be 0 (the identity): the normal needs its own draw
    "Plane": st.builds(lambda n, c, d: Plane(normal=n / np.linalg.norm(n), offset=d, center=c),
                       unit_quats.map(lambda q: q[:3]).filter(lambda n: np.linalg.norm(n) > 0.1),
                       arrays(np.float64, (3,)), finite),
    "Grasp": st.builds(Grasp, kind=st.sampled_from(["frontal", "top_down"]), contacts=arrays(np.float64, (2, 3)),
                       width=st.floats(0, 0.2), rank=finite, metrics=st.dictionaries(small_text, finite, max_size=4),
                       poses=st.dictionaries(small_text, st.builds(Pose, position=arrays(np.float64, (3,)),
                                                                   orientation=unit_quats), max_size=3)),
    "Error": st.builds(Error, code=small_text, message=small_text,
                       detail=st.dictionaries(small_text, json_like, max_size=3)),
    "Ok": st.builds(Ok, info=st.dictionaries(small_text, json_like, max_size=3)),
    "Health": st.builds(Health, service=small_text, instance=small_text, busy=st.integers(0, 100),
                        uptime_s=st.floats(0, 1e6)),
    "Request": st.builds(Request, params=st.dictionaries(small_text, json_like, max_size=4)),
}


def assert_same(a, b):  # noqa: ANN001
    assert type(a) is type(b)
    if dataclasses.is_dataclass(a):
        for f in dataclasses.fields(a):
            assert_same(getattr(a, f.name), getattr(b, f.name))
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b)
    elif isinstance(a, dict):
        assert a.keys() == b.keys()
        for k in a:
            assert_same(a[k], b[k])
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            assert_same(x, y)
    else:
        assert a == b or (isinstance(a, float) and np.isclose(a, b))


def test_every_registered_core_type_has_a_strategy():
    core = {name for name, cls in registered_types().items() if cls.__module__ == "common.messages"}
    assert core <= set(STRATEGIES), core - set(STRATEGIES)


@pytest.mark.parametrize("name", sorted(STRATEGIES))
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_round_trip(name, data):  # noqa: ANN001
    msg = data.draw(STRATEGIES[name])
    back = decode(encode(msg))
    assert_same(msg, back)


def test_payload_is_standard_msgpack():
    frame = RGBDFrame(color=np.zeros((2, 3, 3), np.uint8), depth=np.ones((2, 3), np.uint16),
                      intrinsics=Intrinsics(width=3, height=2, fx=1.0, fy=1.0, cx=1.0, cy=1.0), T_base_camera=np.eye(4))
    raw = msgpack.unpackb(encode(frame), raw=False)
    assert raw["type"] == "RGBDFrame" and raw["v"] == 1
    assert raw["depth"]["nd"] == "<u2" and raw["depth"]["s"] == [2, 3] and len(raw["depth"]["b"]) == 12


def _cloud_wire(**over):  # noqa: ANN003, ANN202
    base = {"type": "PointCloud", "v": 1, "frame": "base",
            "xyz": {"nd": "<f4", "s": [2, 3], "b": np.zeros((2, 3), np.float32).tobytes()}}
    base.update(over)
    return msgpack.packb(base, use_bin_type=True)


@pytest.mark.parametrize("payload, code", [
    (b"", "malformed"),
    (b"\xc1", "malformed"),                               # reserved byte
    (b"\x92\x01", "malformed"),                           # truncated array
    (msgpack.packb([1, 2]), "malformed"),                 # not a map
    (msgpack.packb({"type": "Nope", "v": 1}), "unknown_type"),
    (msgpack.packb({"type": "PointCloud", "v": 99}), "unsupported_version"),
    (msgpack.packb({"type": "PointCloud", "v": 1}), "missing_field"),
    (_cloud_wire(xyz={"nd": "<f8", "s": [2, 3], "b": np.zeros((2, 3)).tobytes()}), "bad_dtype"),
    (_cloud_wire(xyz={"nd": "<f4", "s": [3, 2], "b": np.zeros((3, 2), np.float32).tobytes()}), "bad_shape"),
    (_cloud_wire(xyz={"nd": "<f4", "s": [1000000, 3], "b": b"\x00" * 24}), "bad_shape"),   # shape lies
    (_cloud_wire(xyz={"nd": "<f4", "s": [1, 3], "b": np.array([[0, np.nan, 0]], np.float32).tobytes()}), "non_finite"),
    (_cloud_wire(xyz={"nd": "O", "s": [1], "b": b"\x00" * 8}), "bad_dtype"),
    (_cloud_wire(frame=5), "bad_type"),
    (_cloud_wire(rgb={"nd": "|u1", "s": [1, 3], "b": b"\x00" * 3}), "bad_shape"),           # rows differ from xyz
    (msgpack.packb({"type": "Pose", "v": 1, "position": {"nd": "<f8", "s": [3], "b": b"\x00" * 24},
                    "orientation": {"nd": "<f8", "s": [4], "b": b"\x00" * 32}}), "bad_value"),  # zero quaternion
    (msgpack.packb({"type": "Error", "v": 1, "code": "x", "message": "y", "detail": {"k": float("inf")}}), None),
])
def test_malformed_input_gives_typed_error(payload, code):  # noqa: ANN001
    if code is None:  # free-form maps may carry inf: decoding must still not crash
        decode(payload)
        return
    with pytest.raises(WireError) as err:
        decode(payload)
    assert err.value.code == code, err.value


def test_oversize_payload_rejected_without_parsing():
    class Huge(bytes):
        def __len__(self) -> int:
            return MAX_PAYLOAD_BYTES + 1

    with pytest.raises(WireError) as err:
        decode(Huge(b"\x80"))
    assert err.value.code == "oversize"


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200))
def test_random_bytes_never_crash(blob):  # noqa: ANN001
    try:
        decode(blob)
    except WireError:
        pass


@settings(max_examples=200, deadline=None)
@given(STRATEGIES["PointCloud"], st.integers(0, 400))
def test_truncated_messages_are_rejected(cloud, cut):  # noqa: ANN001
    payload = encode(cloud)
    cut = min(cut, len(payload) - 1)
    with pytest.raises(WireError):
        decode(payload[:cut])


def test_decoded_arrays_share_the_payload_buffer():
    cloud = PointCloud(xyz=np.random.default_rng(0).random((1000, 3), dtype=np.float32))
    payload = encode(cloud)
    back = decode(payload)
    assert not back.xyz.flags.owndata and not back.xyz.flags.writeable
