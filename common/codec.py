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
import types
import typing
from typing import Any, ClassVar, TypeVar

import msgpack
import numpy as np

from common.errors import WireError

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

def _pack_value(value: Any) -> Any:
    if isinstance(value, Message):
        return _to_wire(value)
    if isinstance(value, np.ndarray):
        arr = value.astype(value.dtype.newbyteorder("<"), copy=False)
        arr = np.ascontiguousarray(arr)
        return {"nd": arr.dtype.str, "s": list(arr.shape), "b": memoryview(arr).cast("B") if arr.size else b""}
    if isinstance(value, (list, tuple)):
        return [_pack_value(v) for v in value]
    if isinstance(value, dict):
        return {k: _pack_value(v) for k, v in value.items()}
    if isinstance(value, np.generic):
        return value.item()
    return value


def _to_wire(msg: Message) -> dict[str, Any]:
    out: dict[str, Any] = {"type": type(msg).__name__, "v": type(msg).VERSION}
    for f in dataclasses.fields(msg):  # type: ignore[arg-type]
        out[f.name] = _pack_value(getattr(msg, f.name))
    return out


def encode(msg: Message) -> bytes:
    """Serialise a message to msgpack bytes."""
    return msgpack.packb(_to_wire(msg), use_bin_type=True)


# ----------------------------------------------------------------------------------------------- decode

def decode(payload: bytes | bytearray | memoryview) -> Message:
    """Parse and validate msgpack bytes into the message class named by its ``type``."""
    if payload is None or len(payload) == 0:
        raise WireError("empty payload", code="malformed")
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise WireError("payload too large", code="oversize",
                        detail={"bytes": len(payload), "max": MAX_PAYLOAD_BYTES})
    try:
        raw = msgpack.unpackb(payload, raw=False, strict_map_key=True)
    except Exception as exc:  # msgpack raises several unrelated types for bad input
        raise WireError(f"not valid msgpack: {type(exc).__name__}", code="malformed") from None
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
    hints = _hints(cls)
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        fpath = f"{path}/{f.name}"
        if f.name not in raw:
            has_default = (f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING)
            if has_default:
                continue
            raise WireError(f"missing field {f.name!r} in {type_name}", code="missing_field",
                            detail={"path": fpath})
        kwargs[f.name] = _decode_value(raw[f.name], hints[f.name], f.metadata.get("array"), fpath)
    msg = cls(**kwargs)
    check = getattr(msg, "validate", None)
    if check is not None:
        check()
    return msg


_HINT_CACHE: dict[type, dict[str, Any]] = {}


def _hints(cls: type) -> dict[str, Any]:
    if cls not in _HINT_CACHE:
        _HINT_CACHE[cls] = typing.get_type_hints(cls)
    return _HINT_CACHE[cls]


def _is_optional(tp: Any) -> tuple[bool, Any]:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(tp)) == 2:
            return True, args[0]
    return False, tp


def _bad(kind: str, msg: str, path: str, **detail: Any) -> WireError:
    return WireError(msg, code=kind, detail={"path": path, **detail})


def _decode_value(value: Any, tp: Any, spec: ArraySpec | None, path: str) -> Any:
    optional, tp = _is_optional(tp)
    if value is None:
        if optional:
            return None
        raise _bad("missing_field", "field must not be null", path)
    if spec is not None:
        return _decode_array(value, spec, path)
    origin = typing.get_origin(tp)
    if isinstance(tp, type) and issubclass(tp, Message):
        return _from_wire(value, path, expected=tp)
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise _bad("bad_type", "expected a number", path)
        if not math.isfinite(value):
            raise _bad("non_finite", "number must be finite", path)
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise _bad("bad_type", "expected an integer", path)
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise _bad("bad_type", "expected a boolean", path)
        return value
    if tp is str:
        if not isinstance(value, str):
            raise _bad("bad_type", "expected a string", path)
        return value
    if origin is list:
        if not isinstance(value, list):
            raise _bad("bad_type", "expected a list", path)
        (item_tp,) = typing.get_args(tp) or (Any,)
        return [_decode_value(v, item_tp, None, f"{path}[{i}]") for i, v in enumerate(value)]
    if tp is dict or origin is dict:
        if not isinstance(value, dict):
            raise _bad("bad_type", "expected a map", path)
        return _decode_free(value, path)
    if tp is Any:
        return _decode_free(value, path)
    raise _bad("bad_type", f"unsupported field type {tp!r}", path)


def _decode_free(value: Any, path: str) -> Any:
    """Free-form maps (metadata, figures): nested arrays and messages are decoded, the rest kept."""
    if isinstance(value, dict):
        if "type" in value and "v" in value and isinstance(value.get("type"), str):
            return _from_wire(value, path)
        if set(value) == {"nd", "s", "b"}:
            return _decode_array(value, None, path)
        return {k: _decode_free(v, f"{path}/{k}") for k, v in value.items()}
    if isinstance(value, list):
        return [_decode_free(v, f"{path}[{i}]") for i, v in enumerate(value)]
    return value


def _decode_array(value: Any, spec: ArraySpec | None, path: str) -> np.ndarray:
    if not isinstance(value, dict) or set(value) != {"nd", "s", "b"}:
        raise _bad("bad_type", "expected an array map {nd, s, b}", path)
    dtype_str, shape, data = value["nd"], value["s"], value["b"]
    if not isinstance(dtype_str, str) or not isinstance(shape, list) or not isinstance(data, bytes):
        raise _bad("bad_type", "array map has wrong member types", path)
    try:
        dtype = np.dtype(dtype_str)
    except TypeError:
        raise _bad("bad_dtype", f"unknown dtype {dtype_str!r}", path) from None
    if dtype.kind not in "biuf" or dtype.hasobject:
        raise _bad("bad_dtype", f"dtype {dtype_str!r} is not allowed", path)
    if spec is not None and dtype.str != spec.dtype:
        raise _bad("bad_dtype", f"expected dtype {spec.dtype}, got {dtype.str}", path,
                   expected=spec.dtype, got=dtype.str)
    if len(shape) > 8 or not all(isinstance(d, int) and not isinstance(d, bool) and 0 <= d for d in shape):
        raise _bad("bad_shape", "shape must be a short list of non-negative integers", path, shape=shape)
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
