"""A zero-copy msgpack reader for objscan's messages.

``msgpack.unpackb`` copies every ``bin`` into a new ``bytes``; for a 2 MB frame that copy is half the
cost of decoding. This reader returns ``bin`` values as ``memoryview`` slices of the payload, so
``np.frombuffer`` on them shares the received buffer. Our messages hold few elements (tens of map
entries around a few large arrays), which a small Python parser handles in microseconds.

It is strict: every length is checked against the remaining buffer (a message cannot declare more data
than it carries), nesting is bounded, ext types and non-string map keys are refused, trailing bytes are
an error. Anything wrong raises ``ValueError`` (the codec turns it into a typed ``WireError``).
"""

from __future__ import annotations

import struct
from typing import Any

MAX_DEPTH = 32
MAX_CONTAINER = 1 << 20
MAX_ELEMENTS = 1 << 20
"""Default budget of container elements (array items + map entries, summed over the whole message)."""

_U16 = struct.Struct(">H")
_U32 = struct.Struct(">I")
_U64 = struct.Struct(">Q")
_I8 = struct.Struct(">b")
_I16 = struct.Struct(">h")
_I32 = struct.Struct(">i")
_I64 = struct.Struct(">q")
_F32 = struct.Struct(">f")
_F64 = struct.Struct(">d")


class ElementBudgetExceeded(ValueError):
    """The message declares more container elements than its receiver's budget allows."""


def unpack_view(payload: bytes | bytearray | memoryview, max_elements: int = MAX_ELEMENTS) -> Any:
    """Parse one msgpack object that spans all of ``payload``; bins come back as memoryviews.

    ``max_elements`` bounds the work: every container's declared length is charged to the budget *before*
    its elements are read, so a payload of millions of tiny arrays is refused after at most
    ``max_elements`` items of parsing (unbounded, a 5 MB one costs seconds of pure-Python work).
    """
    view = memoryview(payload).cast("B") if not isinstance(payload, memoryview) else payload.cast("B")
    try:
        obj, end = _read(view, 0, 0, [max_elements])
    except IndexError:
        raise ValueError("truncated message") from None
    if end != len(view):
        raise ValueError(f"{len(view) - end} trailing bytes after the message")
    return obj


def _need(view: memoryview, pos: int, n: int) -> None:
    if n < 0 or pos + n > len(view):
        raise ValueError(f"truncated: need {n} bytes at offset {pos}, have {len(view) - pos}")


def _read(view: memoryview, pos: int, depth: int, budget: list[int]) -> tuple[Any, int]:
    b = view[pos]  # IndexError past the end: reported as truncated
    pos += 1
    if 0xA0 <= b <= 0xBF:  # fixstr: map keys, the most common item
        n = b & 0x1F
        end = pos + n
        if end > len(view):
            raise ValueError(f"truncated string at offset {pos}")
        try:
            return str(view[pos:end], "utf-8"), end
        except UnicodeDecodeError:
            raise ValueError(f"invalid UTF-8 string at offset {pos}") from None
    if b <= 0x7F:
        return b, pos
    if depth > MAX_DEPTH:
        raise ValueError("nesting too deep")
    if b >= 0xE0:
        return b - 0x100, pos
    if 0x80 <= b <= 0x8F:
        return _read_map(view, pos, b & 0x0F, depth, budget)
    if 0x90 <= b <= 0x9F:
        return _read_array(view, pos, b & 0x0F, depth, budget)
    if b == 0xC0:
        return None, pos
    if b == 0xC2:
        return False, pos
    if b == 0xC3:
        return True, pos
    if b in (0xC4, 0xC5, 0xC6):
        n, pos = _read_len(view, pos, b - 0xC4)
        _need(view, pos, n)
        return view[pos:pos + n], pos + n
    if b == 0xCA:
        _need(view, pos, 4)
        return _F32.unpack_from(view, pos)[0], pos + 4
    if b == 0xCB:
        _need(view, pos, 8)
        return _F64.unpack_from(view, pos)[0], pos + 8
    if 0xCC <= b <= 0xCF:
        size = 1 << (b - 0xCC)
        _need(view, pos, size)
        if size == 1:
            return view[pos], pos + 1
        fmt = {2: _U16, 4: _U32, 8: _U64}[size]
        return fmt.unpack_from(view, pos)[0], pos + size
    if 0xD0 <= b <= 0xD3:
        size = 1 << (b - 0xD0)
        _need(view, pos, size)
        fmt = {1: _I8, 2: _I16, 4: _I32, 8: _I64}[size]
        return fmt.unpack_from(view, pos)[0], pos + size
    if b in (0xD9, 0xDA, 0xDB):
        n, pos = _read_len(view, pos, b - 0xD9)
        return _read_str(view, pos, n)
    if b in (0xDC, 0xDD):
        n, pos = _read_len(view, pos, b - 0xDC + 1)
        return _read_array(view, pos, n, depth, budget)
    if b in (0xDE, 0xDF):
        n, pos = _read_len(view, pos, b - 0xDE + 1)
        return _read_map(view, pos, n, depth, budget)
    raise ValueError(f"unsupported msgpack type byte 0x{b:02x} at offset {pos - 1}")


def _read_len(view: memoryview, pos: int, width_code: int) -> tuple[int, int]:
    """Length prefix of 1, 2 or 4 bytes (width_code 0, 1, 2)."""
    if width_code == 0:
        _need(view, pos, 1)
        return view[pos], pos + 1
    if width_code == 1:
        _need(view, pos, 2)
        return _U16.unpack_from(view, pos)[0], pos + 2
    _need(view, pos, 4)
    return _U32.unpack_from(view, pos)[0], pos + 4


def _read_str(view: memoryview, pos: int, n: int) -> tuple[str, int]:
    _need(view, pos, n)
    try:
        return str(view[pos:pos + n], "utf-8"), pos + n
    except UnicodeDecodeError:
        raise ValueError(f"invalid UTF-8 string at offset {pos}") from None


def _charge(budget: list[int], n: int) -> None:
    """Take ``n`` elements from the message's budget (a one-item list shared by the whole parse)."""
    budget[0] -= n
    if budget[0] < 0:
        raise ElementBudgetExceeded("message holds more elements than this key accepts")


def _read_array(view: memoryview, pos: int, n: int, depth: int, budget: list[int]) -> tuple[list[Any], int]:
    if n > MAX_CONTAINER or n > len(view) - pos:  # every element takes at least one byte
        raise ValueError(f"array of {n} elements cannot fit")
    _charge(budget, n)
    out = []
    for _ in range(n):
        item, pos = _read(view, pos, depth + 1, budget)
        out.append(item)
    return out, pos


def _read_map(view: memoryview, pos: int, n: int, depth: int, budget: list[int]) -> tuple[dict[str, Any], int]:
    if n > MAX_CONTAINER or 2 * n > len(view) - pos:
        raise ValueError(f"map of {n} entries cannot fit")
    _charge(budget, n)
    out: dict[str, Any] = {}
    for _ in range(n):
        key, pos = _read(view, pos, depth + 1, budget)
        if not isinstance(key, str):
            raise ValueError("map keys must be strings")
        value, pos = _read(view, pos, depth + 1, budget)
        out[key] = value
    return out, pos
