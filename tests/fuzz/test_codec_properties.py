"""Property-based fuzzing of the decoders: ``common.codec.decode``, ``common.msgpack_view.unpack_view`` and
every registered message type.

The promise under test: whatever bytes arrive, decoding returns a valid message or raises ``WireError``
(``ValueError`` for the bare msgpack reader) — never another exception, never a hang, never an allocation
driven by a size the payload only claims. Budget: ``OBJSCAN_FUZZ_EXAMPLES`` examples per property
(default 150; CI keeps the default, a long local run may raise it).
"""

from __future__ import annotations

import math
import os
import struct
import time
import tracemalloc

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from common.codec import MAX_PAYLOAD_BYTES, Message, decode, encode
from common.errors import WireError
from common.msgpack_view import unpack_view
from tests.fuzz.strategies import MESSAGE_TYPES, any_valid_message, hostile_wire, pack, valid_message

pytestmark = pytest.mark.filterwarnings("ignore::hypothesis.errors.NonInteractiveExampleWarning")

EXAMPLES = int(os.environ.get("OBJSCAN_FUZZ_EXAMPLES", "150"))
fuzz = settings(max_examples=EXAMPLES, deadline=2000, suppress_health_check=[HealthCheck.too_slow,
                                                                             HealthCheck.data_too_large])


def decode_or_wire_error(payload: bytes) -> Message | None:
    """Decode; a WireError is a correct refusal (None), anything else fails the test."""
    try:
        msg = decode(payload)
    except WireError as exc:
        assert exc.code and isinstance(exc.code, str)
        return None
    assert isinstance(msg, Message)
    return msg


def _assert_canonical(msg: Message) -> None:
    """A decoded message re-encodes and decodes to the same bytes (no half-valid state slipped through)."""
    again = encode(msg)
    assert encode(decode(again)) == again


# ------------------------------------------------------------------------------------------- codec
@fuzz
@given(st.binary(max_size=512))
def test_random_bytes_never_crash_the_decoder(payload):
    msg = decode_or_wire_error(payload)
    if msg is not None:
        _assert_canonical(msg)


@fuzz
@given(any_valid_message)
def test_valid_messages_round_trip_exactly_or_fail_their_own_validation(msg):
    payload = msg.encode()
    out = decode_or_wire_error(payload)
    if out is None:  # the instance broke its class's invariants (e.g. a move without a target): refused
        return
    assert type(out) is type(msg)
    assert encode(out) == payload


@fuzz
@given(any_valid_message, st.data())
def test_truncated_messages_are_refused(msg, data):
    payload = msg.encode()
    cut = data.draw(st.integers(0, len(payload) - 1))
    with pytest.raises(WireError):
        decode(payload[:cut])


@fuzz
@given(any_valid_message, st.data())
def test_mutated_messages_decode_or_are_refused(msg, data):
    payload = bytearray(msg.encode())
    for _ in range(data.draw(st.integers(1, 4))):
        pos = data.draw(st.integers(0, len(payload) - 1))
        payload[pos] = data.draw(st.integers(0, 255))
    if data.draw(st.booleans()):
        payload += data.draw(st.binary(min_size=1, max_size=8))  # trailing garbage
    out = decode_or_wire_error(bytes(payload))
    if out is not None:
        _assert_canonical(out)


@pytest.mark.parametrize("type_name", sorted(MESSAGE_TYPES))
def test_every_message_type_refuses_hostile_fields(type_name):
    """Wrong types, NaN/inf, huge integers, lying arrays, missing and extra fields, for each type."""
    cls = MESSAGE_TYPES[type_name]
    outcomes: dict[str, int] = {}

    @settings(max_examples=max(20, EXAMPLES // 3), deadline=2000,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(hostile_wire(cls))
    def check(raw):
        out = decode_or_wire_error(pack(raw))
        outcomes["ok" if out is not None else "refused"] = outcomes.get("ok" if out is not None else "refused", 0) + 1
        if out is not None:
            _assert_canonical(out)

    check()
    assert outcomes.get("refused", 0) > 0, f"no hostile {type_name} was ever refused: the strategy is broken"


@fuzz
@given(any_valid_message)
def test_every_valid_message_can_be_parsed_as_its_own_class_only(msg):
    payload = msg.encode()
    out = decode_or_wire_error(payload)
    if out is None:
        return
    other = next(c for n, c in sorted(MESSAGE_TYPES.items()) if c is not type(msg))
    with pytest.raises(WireError) as err:
        other.decode(payload)
    assert err.value.code == "unexpected_type"


# ------------------------------------------------------------------------------------------- msgpack_view
msgpack_objects = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**63), 2**64 - 1) | st.floats(allow_nan=False) | st.text(max_size=20)
    | st.binary(max_size=40),
    lambda children: st.lists(children, max_size=5) | st.dictionaries(st.text(max_size=8), children, max_size=5),
    max_leaves=30)


def _plain(obj):
    if isinstance(obj, memoryview):
        return obj.tobytes()
    if isinstance(obj, list):
        return [_plain(v) for v in obj]
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    return obj


@fuzz
@given(msgpack_objects)
def test_unpack_view_agrees_with_msgpack(obj):
    payload = msgpack.packb(obj, use_bin_type=True)
    assert _plain(unpack_view(payload)) == msgpack.unpackb(payload, raw=False, strict_map_key=False)


@fuzz
@given(st.binary(max_size=256))
def test_unpack_view_raises_only_value_error_and_agrees_when_it_parses(payload):
    try:
        obj = unpack_view(payload)
    except ValueError:
        return
    ref = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    assert msgpack.packb(_plain(obj)) == msgpack.packb(ref)  # packed: a NaN float equals itself


# ------------------------------------------------------------------------------------------- sizes and depth
_HUGE_HEADERS = [
    b"\xc6\xff\xff\xff\xff",  # bin 32 of 4 GiB
    b"\xc5\xff\xff",  # bin 16
    b"\xdb\xff\xff\xff\xff",  # str 32
    b"\xdd\xff\xff\xff\xff",  # array 32 of 4 G elements
    b"\xdf\xff\xff\xff\xff",  # map 32
    b"\xdc\xff\xff",  # array 16
    b"\xde\xff\xff",  # map 16
]


@pytest.mark.parametrize("header", _HUGE_HEADERS, ids=lambda h: h[:1].hex())
@pytest.mark.parametrize("where", ["top", "array_bytes", "field"])
def test_declared_sizes_do_not_allocate(header, where):
    """A payload that claims gigabytes is refused in microseconds without allocating what it claims."""
    if where == "top":
        payload = header + b"\x00" * 16
    elif where == "array_bytes":  # a PointCloud whose array bytes claim to be huge
        payload = (b"\x83\xa4type\xaaPointCloud\xa1v\x01\xa3xyz\x83\xa2nd\xa3<f4\xa1s\x92\xce\xff\xff\xff\xff\x03\xa1b"
                   + header + b"\x00" * 64)
    else:
        payload = b"\x83\xa4type\xa7Request\xa1v\x01\xa6params" + header + b"\x00" * 64
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(WireError):
            decode(payload)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert time.perf_counter() - t0 < 0.5
    assert peak < 1024 * 1024, f"decoding a {len(payload)}-byte payload allocated {peak} bytes"


def test_lying_shapes_do_not_allocate():
    """Shapes claiming 2**62 elements (or a huge dimension times zero) are refused before any allocation."""
    for shape in ([2**31, 2**31], [0, 2**63], [2**64 - 1, 0], [0, MAX_PAYLOAD_BYTES + 1], [3] * 9):
        raw = {"type": "Request", "v": 1, "params": {"a": {"nd": "<f8", "s": shape, "b": b""}}}
        tracemalloc.start()
        try:
            with pytest.raises(WireError) as err:
                decode(pack(raw))
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert err.value.code == "bad_shape", shape
        assert peak < 1024 * 1024, f"{shape}: {peak} bytes"


@pytest.mark.parametrize("depth", [33, 200, 5000])
def test_deep_nesting_is_refused_not_a_recursion_error(depth):
    payload = b"\x91" * depth + b"\x00"
    with pytest.raises(WireError):
        decode(payload)
    payload = b"\x81\xa1a" * depth + b"\x00"
    with pytest.raises(WireError):
        decode(payload)


def test_oversize_payload_is_refused_before_parsing():
    class Huge(bytes):
        def __len__(self) -> int:  # a payload that says it is larger than the limit
            return MAX_PAYLOAD_BYTES + 1

    with pytest.raises(WireError) as err:
        decode(Huge(b"\x80"))
    assert err.value.code == "oversize"


def test_floats_nan_and_inf_are_refused_everywhere_finite_is_required():
    for bad in (math.nan, math.inf, -math.inf):
        raw = {"type": "GripperRequest", "v": 1, "opening": bad, "force": 10.0}
        with pytest.raises(WireError) as err:
            decode(pack(raw))
        assert err.value.code == "non_finite"
        arr = np.array([0.0, 0.0, bad])
        raw = {"type": "SceneRequest", "v": 1, "center": {"nd": "<f8", "s": [3], "b": arr.tobytes()},
               "extent": {"nd": "<f8", "s": [3], "b": np.ones(3).tobytes()}, "yaw": 0.0}
        with pytest.raises(WireError) as err:
            decode(pack(raw))
        assert err.value.code == "non_finite"


def test_f32_and_f64_nan_bit_patterns_in_msgpack_floats():
    for payload in (b"\xca" + struct.pack(">f", math.nan), b"\xcb" + struct.pack(">d", math.inf)):
        raw_prefix = b"\x84\xa4type\xaeGripperRequest\xa1v\x01\xa7opening"
        with pytest.raises(WireError):
            decode(raw_prefix + payload + b"\xa5force\x0a")


def test_valid_message_strategy_covers_every_registered_type():
    for name, cls in MESSAGE_TYPES.items():
        msg = valid_message(cls).example()
        assert type(msg) is cls, name
