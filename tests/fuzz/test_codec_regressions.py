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


@pytest.mark.parametrize("dtype", [",f4", ",", "i4,,f8", "(", "f8)", "[('a', 'f8')]", "\x00", "f" * 10000])
def test_dtype_strings_numpy_cannot_parse_are_wire_errors(dtype):
    """np.dtype(",f4") raises SyntaxError (not TypeError): it escaped decode() and would end a subscriber's
    receive loop, which only catches WireError (atheris finding)."""
    raw = {"type": "PointCloud", "v": 1, "xyz": {"nd": dtype, "s": [0, 3], "b": b""}}
    with pytest.raises(WireError) as err:
        decode(pack(raw))
    assert err.value.code == "bad_dtype"
