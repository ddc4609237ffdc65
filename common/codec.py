"""msgpack codec for objscan wire messages, with strict validation.

Wire form: a msgpack map with ``type`` (the message class name), ``v`` (schema version) and one entry
per field. numpy arrays travel as a map ``{"nd": dtype, "s": shape, "b": raw little-endian bytes}``;
they are packed straight from the array's buffer and decoded with ``np.frombuffer`` (no per-element
work, no copy beyond the one msgpack makes of the bytes).

Decoding checks everything a hostile or buggy peer could get wrong (unknown type or version, missing
or extra-typed fields, dtype, shape, byte length, NaN/inf, emptiness, payload size) and raises
``WireError`` with a stable code, never anything else.
"""

from __future__ import annotations

import dataclasses
import math
import struct
import types
import typing
from collections.abc import Callable
from typing import Any, ClassVar, TypeVar

import msgpack
import numpy as np

from common.errors import WireError
from common.msgpack_view import MAX_ELEMENTS, ElementBudgetExceeded, unpack_view

MAX_PAYLOAD_BYTES = 512 * 1024 * 1024
"""Largest message accepted. A 1M-point colored cloud with normals is ~27 MB; a 1280x720 RGB-D ~4.6 MB."""

_REGISTRY: dict[str, type[Message]] = {}
M = TypeVar("M", bound="Message")


@dataclasses.dataclass(frozen=True)
class ArraySpec:
    """What an array field must look like. ``shape`` uses ``None`` for a free dimension."""

    dtype: str
    shape: tuple[int | None, ...]
    finite: bool = True
    allow_empty: bool = True


def array_field(dtype: str, shape: tuple[int | None, ...], *, finite: bool = True,
                allow_empty: bool = True, optional: bool = False) -> Any:
    """Declare a numpy array field on a message dataclass."""
    spec = ArraySpec(np.dtype(dtype).newbyteorder("<").str, shape, finite, allow_empty)
    if optional:
        return dataclasses.field(default=None, metadata={"array": spec})
    return dataclasses.field(metadata={"array": spec})


class Message:
    """Base of every wire message. Subclasses are dataclasses with ``TYPE`` implied by the class name."""

    VERSION: ClassVar[int] = 1

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.__name__ in _REGISTRY and _REGISTRY[cls.__name__] is not cls:
            raise TypeError(f"duplicate wire type {cls.__name__}")
        _REGISTRY[cls.__name__] = cls

    def encode(self) -> bytes:
        return encode(self)

    @classmethod
    def decode(cls: type[M], payload: bytes | bytearray | memoryview) -> M:
        msg = decode(payload)
        if not isinstance(msg, cls):
            raise WireError(f"expected {cls.__name__}, got {type(msg).__name__}", code="unexpected_type",
                            detail={"expected": cls.__name__, "got": type(msg).__name__})
        return msg


def registered_types() -> dict[str, type[Message]]:
    """All message classes known to the codec, by wire type name."""
    return dict(_REGISTRY)


# ----------------------------------------------------------------------------------------------- encode

_PACK = msgpack.Packer(use_bin_type=True, autoreset=True)


def _bin_header(n: int) -> bytes:
    """msgpack ``bin`` header for ``n`` bytes (bin 8/16/32 as the spec says)."""
    if n < 1 << 8:
        return struct.pack(">BB", 0xC4, n)
    if n < 1 << 16:
        return struct.pack(">BH", 0xC5, n)
    return struct.pack(">BI", 0xC6, n)


# an array on the wire is the map {nd: dtype string, s: shape list, b: raw little-endian bytes}
_ARRAY_KEYS = frozenset({"nd", "s", "b"})
_ARRAY_HEAD = _PACK.pack_map_header(3) + _PACK.pack("nd")
_SHAPE_KEY = _PACK.pack("s")
_DATA_KEY = _PACK.pack("b")
_LAYOUTS: dict[type, tuple[bytes, list[tuple[str, bytes]]]] = {}


def _message_layout(cls: type[Message]) -> tuple[bytes, list[tuple[str, bytes]]]:
    """A message class's constant bytes, packed once: the map header with ``type`` and ``v``, and each
    field's packed name (encoding a frame is then mostly its one copy of the pixels)."""
    layout = _LAYOUTS.get(cls)
    if layout is None:
        fields = dataclasses.fields(cls)  # type: ignore[arg-type]
        head = b"".join((_PACK.pack_map_header(len(fields) + 2), _PACK.pack("type"), _PACK.pack(cls.__name__),
                         _PACK.pack("v"), _PACK.pack(cls.VERSION)))
        layout = _LAYOUTS[cls] = (head, [(f.name, _PACK.pack(f.name)) for f in fields])
    return layout


def _emit(value: Any, out: list[Any]) -> None:
    """Append the msgpack encoding of ``value`` to ``out`` as chunks.

    Array data is appended as a memoryview of the array itself, so the only copy of a large buffer is the
    final ``b"".join``. The result is standard msgpack that any decoder reads.
    """
    if isinstance(value, Message):
        head, fields = _message_layout(type(value))
        out.append(head)
        for name, key in fields:
            out.append(key)
            _emit(getattr(value, name), out)
    elif isinstance(value, np.ndarray):
        arr = np.ascontiguousarray(value.astype(value.dtype.newbyteorder("<"), copy=False))
        out.append(b"".join((_ARRAY_HEAD, _PACK.pack(arr.dtype.str), _SHAPE_KEY, _PACK.pack(list(arr.shape)),
                             _DATA_KEY, _bin_header(arr.nbytes))))
        if arr.nbytes:
            out.append(memoryview(arr).cast("B"))
    elif isinstance(value, dict):
        out.append(_PACK.pack_map_header(len(value)))
        for k, v in value.items():
            out.append(_PACK.pack(k))
            _emit(v, out)
    elif isinstance(value, (list, tuple)):
        out.append(_PACK.pack_array_header(len(value)))
        for v in value:
            _emit(v, out)
    elif isinstance(value, np.generic):
        out.append(_PACK.pack(value.item()))
    else:
        out.append(_PACK.pack(value))


def encode(msg: Message) -> bytes:
    """Serialise a message to msgpack bytes (large arrays are copied exactly once)."""
    chunks: list[Any] = []
    _emit(msg, chunks)
    return b"".join(chunks)


# ----------------------------------------------------------------------------------------------- decode

def decode(payload: bytes | bytearray | memoryview, *, max_bytes: int = MAX_PAYLOAD_BYTES,
           max_elements: int = MAX_ELEMENTS) -> Message:
    """Parse and validate msgpack bytes into the message class named by its ``type``.

    Arrays share ``payload``'s memory (read-only views): no copy of the bulk data. ``max_bytes`` and
    ``max_elements`` are the receiving key's budget (``common.runtime.Budget``): a payload over either is
    refused with code ``oversize`` / ``too_many_elements`` before (or early in) parsing.
    """
    if payload is None or len(payload) == 0:
        raise WireError("empty payload", code="malformed")
    limit = min(max_bytes, MAX_PAYLOAD_BYTES)
    if len(payload) > limit:
        raise WireError("payload too large", code="oversize", detail={"bytes": len(payload), "max": limit})
    try:
        raw = unpack_view(payload, max_elements)
    except ElementBudgetExceeded:
        raise WireError("payload holds too many elements", code="too_many_elements",
                        detail={"max": max_elements}) from None
    except (ValueError, TypeError, struct.error) as exc:
        raise WireError(f"not valid msgpack: {exc}", code="malformed") from None
    return _from_wire(raw, path="")


def _from_wire(raw: Any, path: str, expected: type[Message] | None = None) -> Message:
    if not isinstance(raw, dict):
        raise WireError("message is not a map", code="malformed", detail={"path": path or "/"})
    type_name = raw.get("type")
    cls = _REGISTRY.get(type_name) if isinstance(type_name, str) else None
    if cls is None:
        raise WireError(f"unknown message type {type_name!r}", code="unknown_type", detail={"path": path or "/"})
    if expected is not None and not issubclass(cls, expected):
        raise WireError(f"expected {expected.__name__}, got {type_name}", code="unexpected_type",
                        detail={"path": path or "/"})
    version = raw.get("v")
    if version != cls.VERSION:
        raise WireError(f"{type_name} schema version {version!r} is not supported (expected {cls.VERSION})",
                        code="unsupported_version", detail={"path": path or "/"})
    kwargs: dict[str, Any] = {}
    for name, suffix, decoder, required in _plan(cls):
        value = raw.get(name, _ABSENT)
        if value is _ABSENT:
            if required:
                raise WireError(f"missing field {name!r} in {type_name}", code="missing_field",
                                detail={"path": path + suffix})
            continue
        kwargs[name] = decoder(value, path + suffix)
    msg = cls(**kwargs)
    check = getattr(msg, "validate", None)
    if check is not None:
        check()
    return msg


Decoder = Callable[[Any, str], Any]
_PLANS: dict[type, list[tuple[str, str, Decoder, bool]]] = {}
_ABSENT = object()


def _plan(cls: type[Message]) -> list[tuple[str, str, Decoder, bool]]:
    """Per-class list of (field, its path suffix, decoder, required), built once from the type hints."""
    plan = _PLANS.get(cls)
    if plan is None:
        hints = typing.get_type_hints(cls)
        plan = []
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
            plan.append((f.name, "/" + f.name, _decoder_for(hints[f.name], f.metadata.get("array")), required))
        _PLANS[cls] = plan
    return plan


def _is_optional(tp: Any) -> tuple[bool, Any]:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(tp)) == 2:
            return True, args[0]
    return False, tp


def _bad(kind: str, msg: str, path: str, **detail: Any) -> WireError:
    return WireError(msg, code=kind, detail={"path": path, **detail})


def _decoder_for(tp: Any, spec: ArraySpec | None) -> Decoder:
    """A function that validates and converts one wire value of type ``tp``."""
    optional, tp = _is_optional(tp)
    inner = _inner_decoder(tp, spec)

    def decode_value(value: Any, path: str) -> Any:
        if value is None:
            if optional:
                return None
            raise _bad("missing_field", "field must not be null", path)
        return inner(value, path)

    return decode_value


def _inner_decoder(tp: Any, spec: ArraySpec | None) -> Decoder:
    if spec is not None:
        return lambda v, p: _decode_array(v, spec, p)
    origin = typing.get_origin(tp)
    if isinstance(tp, type) and issubclass(tp, Message):
        return lambda v, p: _from_wire(v, p, expected=tp)
    if tp is float:
        return _decode_float
    if tp is int:
        return _decode_int
    if tp is bool:
        return _decode_bool
    if tp is str:
        return _decode_str
    if origin is list:
        (item_tp,) = typing.get_args(tp) or (Any,)
        item = _decoder_for(item_tp, None)

        def decode_list(v: Any, p: str) -> list[Any]:
            if not isinstance(v, list):
                raise _bad("bad_type", "expected a list", p)
            return [item(x, f"{p}[{i}]") for i, x in enumerate(v)]

        return decode_list
    if tp is dict or origin is dict:
        def decode_map(v: Any, p: str) -> Any:
            if not isinstance(v, dict):
                raise _bad("bad_type", "expected a map", p)
            return _decode_free(v, p)

        return decode_map
    if tp is Any:
        return _decode_free
    raise TypeError(f"unsupported wire field type {tp!r}")


def _decode_float(value: Any, path: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _bad("bad_type", "expected a number", path)
    if not math.isfinite(value):
        raise _bad("non_finite", "number must be finite", path)
    return float(value)


def _decode_int(value: Any, path: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise _bad("bad_type", "expected an integer", path)
    return value


def _decode_bool(value: Any, path: str) -> bool:
    if not isinstance(value, bool):
        raise _bad("bad_type", "expected a boolean", path)
    return value


def _decode_str(value: Any, path: str) -> str:
    if not isinstance(value, str):
        raise _bad("bad_type", "expected a string", path)
    return value


def _decode_free(value: Any, path: str) -> Any:
    """Free-form maps (metadata, figures): nested arrays and messages are decoded, the rest kept."""
    if isinstance(value, dict):
        if "type" in value and "v" in value and isinstance(value.get("type"), str):
            return _from_wire(value, path)
        if value.keys() == _ARRAY_KEYS:
            return _decode_array(value, None, path)
        return {k: _decode_free(v, f"{path}/{k}") for k, v in value.items()}
    if isinstance(value, list):
        return [_decode_free(v, f"{path}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, memoryview):
        return value.tobytes()
    return value


_ALLOWED_DTYPES: dict[str, np.dtype] = {}  # dtype strings already parsed and allowed (a few: '<f4', '|u1', ...)


def _wire_dtype(dtype_str: str, path: str) -> np.dtype:
    """The numpy dtype a wire ``nd`` names, if it is a plain number type; parsed once per distinct string."""
    dtype = _ALLOWED_DTYPES.get(dtype_str)
    if dtype is not None:
        return dtype
    try:
        dtype = np.dtype(dtype_str)
    except Exception:  # TypeError, but also SyntaxError for ",f4" and ValueError (fuzzing finding)
        raise _bad("bad_dtype", f"unknown dtype {dtype_str!r}", path) from None
    if dtype.kind not in "biuf" or dtype.hasobject:
        raise _bad("bad_dtype", f"dtype {dtype_str!r} is not allowed", path)
    if len(_ALLOWED_DTYPES) < 64:  # bounded: a hostile sender cycling spellings cannot grow it
        _ALLOWED_DTYPES[dtype_str] = dtype
    return dtype


def _decode_array(value: Any, spec: ArraySpec | None, path: str) -> np.ndarray:
    if not isinstance(value, dict) or value.keys() != _ARRAY_KEYS:
        raise _bad("bad_type", "expected an array map {nd, s, b}", path)
    dtype_str, shape, data = value["nd"], value["s"], value["b"]
    if not isinstance(dtype_str, str) or not isinstance(shape, list) or not isinstance(data, (bytes, memoryview)):
        raise _bad("bad_type", "array map has wrong member types", path)
    dtype = _wire_dtype(dtype_str, path)
    if spec is not None and dtype.str != spec.dtype:
        raise _bad("bad_dtype", f"expected dtype {spec.dtype}, got {dtype.str}", path,
                   expected=spec.dtype, got=dtype.str)
    # A dimension above the payload limit cannot be real; with another dimension 0 it would pass the
    # byte-length check and then crash reshape (fuzzing finding, tests/fuzz/test_codec_regressions.py).
    if len(shape) > 8 or not all(isinstance(d, int) and not isinstance(d, bool) and 0 <= d <= MAX_PAYLOAD_BYTES
                                 for d in shape):
        raise _bad("bad_shape", "shape must be a short list of non-negative integers within the payload limit",
                   path, shape=shape)
    count = math.prod(shape)
    if count * dtype.itemsize != len(data):
        raise _bad("bad_shape", "byte length does not match dtype and shape", path,
                   shape=shape, bytes=len(data))
    if spec is not None:
        if len(shape) != len(spec.shape) or any(e is not None and e != d for e, d in zip(spec.shape, shape)):
            raise _bad("bad_shape", f"expected shape {spec.shape}, got {tuple(shape)}", path,
                       expected=list(spec.shape), got=shape)
        if count == 0 and not spec.allow_empty:
            raise _bad("empty", "array must not be empty", path)
    arr = np.frombuffer(data, dtype=dtype).reshape(shape)
    if dtype.kind == "f" and (spec is None or spec.finite) and count and not np.isfinite(arr).all():
        raise _bad("non_finite", "array contains NaN or inf", path)
    return arr
