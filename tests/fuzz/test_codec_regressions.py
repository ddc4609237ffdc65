"""Inputs the fuzzers found that once crashed a decoder, kept so they never come back."""

from __future__ import annotations

import pytest

from common.codec import decode
from common.errors import WireError
from tests.fuzz.strategies import pack

ARRAY_CASES = [
    # A free-form array (in a dict field) with one dimension 0 and another beyond intp passed the byte-length
    # check (0 elements, 0 bytes) and crashed numpy's reshape with ValueError "array is too big".
    ({"type": "Request", "v": 1, "params": {"a": {"nd": "<f8", "s": [0, 2**62, 2**62], "b": b""}}}, "bad_shape"),
    ({"type": "Request", "v": 1, "params": {"a": {"nd": "<f8", "s": [0, 2**64 - 1], "b": b""}}}, "bad_shape"),
    # the same through a typed field with free dimensions (RGBDFrame.color is (None, None, 3))
    ({"type": "RGBDFrame", "v": 1, "color": {"nd": "|u1", "s": [2**63, 0, 3], "b": b""}}, "bad_shape"),
]


@pytest.mark.parametrize(("raw", "code"), ARRAY_CASES)
def test_huge_dimension_with_zero_elements_is_a_wire_error(raw, code):
    with pytest.raises(WireError) as err:
        decode(pack(raw))
    assert err.value.code == code
