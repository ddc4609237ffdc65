"""Hypothesis strategies for objscan's wire messages: valid ones, and hostile variations of them.

Valid messages are derived from each registered class's fields (type hints and array specs), so a message
type added later is fuzzed without touching this file. Hostile wire maps keep the ``type``/``v`` header of
a real class (so decoding goes deep into field validation) and replace, drop or add fields with what a
buggy or malicious peer could send: wrong types, NaN/inf, huge integers, arrays whose shape, dtype or byte
length lie, nested messages of the wrong type.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from typing import Any

import msgpack
import numpy as np
from hypothesis import strategies as st

import common.api  # noqa: F401 - registers the API message types
import common.messages  # noqa: F401 - registers the core message types
from common.codec import ArraySpec, Message, _is_optional, registered_types
from services.registration.api import PairJobMessage  # noqa: F401 - registers the pair job messages

MESSAGE_TYPES: dict[str, type[Message]] = registered_types()

# ------------------------------------------------------------------------------------------ valid values
msgpack_ints = st.integers(-(2**63), 2**64 - 1)
"""What msgpack can carry: a sender cannot even encode a larger integer."""
finite = st.floats(allow_nan=False, allow_infinity=False, width=64, min_value=-1e6, max_value=1e6)
small_text = st.text(max_size=12)


def _unit(n: int) -> st.SearchStrategy[np.ndarray]:
    return st.lists(finite, min_size=n, max_size=n).map(
        lambda v: (np.asarray(v) / np.linalg.norm(v)) if np.linalg.norm(v) > 1e-3 else np.eye(n)[-1])


def _array_for(spec: ArraySpec, *, rows: int | None = None) -> st.SearchStrategy[np.ndarray]:
    dtype = np.dtype(spec.dtype)

    def build(draw: Any) -> np.ndarray:
        shape = tuple(d if d is not None else (rows if rows is not None and i == 0 else draw(st.integers(0, 4)))
                      for i, d in enumerate(spec.shape))
        if not spec.allow_empty and math.prod(shape) == 0:
            shape = tuple(max(1, d) for d in shape)
        if dtype.kind == "f":
            flat = draw(st.lists(finite, min_size=math.prod(shape), max_size=math.prod(shape)))
        elif dtype.kind == "u":
            flat = draw(st.lists(st.integers(0, 255), min_size=math.prod(shape), max_size=math.prod(shape)))
        else:
            flat = draw(st.lists(st.integers(-100, 100), min_size=math.prod(shape), max_size=math.prod(shape)))
        return np.asarray(flat, dtype=dtype).reshape(shape)

    return st.composite(lambda draw: build(draw))()


# Fields whose validity couples to other fields (a class's ``validate``): valid values built together.
def _special(cls: type[Message]) -> st.SearchStrategy[dict[str, Any]] | None:
    name = cls.__name__
    if name == "Intrinsics":
        return st.fixed_dictionaries({"width": st.integers(1, 4096), "height": st.integers(1, 4096),
                                      "fx": st.floats(1, 2000), "fy": st.floats(1, 2000), "cx": finite, "cy": finite})
    if name == "Pose":
        return st.fixed_dictionaries({"position": _array_for(ArraySpec("<f8", (3,))), "orientation": _unit(4)})
    if name == "Plane":
        return st.fixed_dictionaries({"normal": _unit(3), "offset": finite,
                                      "center": _array_for(ArraySpec("<f8", (3,)))})
    if name == "Transform":
        return st.just({"matrix": np.eye(4)})
    if name == "PointCloud":
        return st.integers(0, 5).flatmap(lambda n: st.fixed_dictionaries({
            "xyz": _array_for(ArraySpec("<f4", (None, 3)), rows=n),
            "rgb": st.none() | _array_for(ArraySpec("|u1", (None, 3)), rows=n),
            "normals": st.none() | _array_for(ArraySpec("<f4", (None, 3)), rows=n)}))
    if name == "JointState":
        return st.lists(small_text, max_size=6).map(lambda names: {
            "names": names, "position": np.zeros(len(names))})
    if name == "RGBDFrame":
        def frame(size: tuple[int, int]) -> dict[str, Any]:
            w, h = size
            return {"color": np.zeros((h, w, 3), np.uint8), "depth": np.zeros((h, w), np.uint16),
                    "intrinsics": common.messages.Intrinsics(width=w, height=h, fx=500.0, fy=500.0, cx=w / 2,
                                                             cy=h / 2),
                    "T_base_camera": np.eye(4)}
        return st.tuples(st.integers(1, 6), st.integers(1, 6)).map(frame)
    return None


def valid_value(tp: Any, spec: ArraySpec | None, depth: int = 0) -> st.SearchStrategy[Any]:
    """A strategy of valid Python values for a field of type ``tp``."""
    optional, tp = _is_optional(tp)
    base: st.SearchStrategy[Any]
    if spec is not None:
        base = _array_for(spec)
    elif isinstance(tp, type) and issubclass(tp, Message):
        base = valid_message(tp, depth + 1)
    elif tp is float:
        base = finite
    elif tp is int:
        base = st.integers(-(2**31), 2**31)
    elif tp is bool:
        base = st.booleans()
    elif tp is str:
        base = small_text
    elif typing.get_origin(tp) is list:
        (item,) = typing.get_args(tp) or (Any,)
        base = st.lists(valid_value(item, None, depth + 1), max_size=2 if depth else 3)
    elif tp is dict or typing.get_origin(tp) is dict or tp is Any:
        base = st.dictionaries(small_text, st.none() | msgpack_ints | finite | small_text, max_size=3)
    else:
        raise TypeError(tp)
    return (st.none() | base) if optional else base


def valid_message(cls: type[Message], depth: int = 0) -> st.SearchStrategy[Message]:
    """Instances of ``cls`` that pass its validation."""
    hints = typing.get_type_hints(cls)
    fields = {}
    special = _special(cls)
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        fields[f.name] = valid_value(hints[f.name], f.metadata.get("array"), depth)
    if special is None:
        return st.fixed_dictionaries(fields).map(lambda kw: cls(**kw))

    def merge(draw: Any) -> Message:
        kw = draw(st.fixed_dictionaries({k: v for k, v in fields.items() if k not in _SPECIAL_KEYS[cls.__name__]}))
        kw.update(draw(special))
        return cls(**kw)

    return st.composite(lambda draw: merge(draw))()


_SPECIAL_KEYS = {"Intrinsics": {"width", "height", "fx", "fy", "cx", "cy"}, "Pose": {"position", "orientation"},
                 "Plane": {"normal", "offset", "center"}, "Transform": {"matrix"},
                 "PointCloud": {"xyz", "rgb", "normals"}, "JointState": {"names", "position"},
                 "RGBDFrame": {"color", "depth", "intrinsics", "T_base_camera"}}

any_valid_message = st.sampled_from(sorted(MESSAGE_TYPES)).flatmap(lambda n: valid_message(MESSAGE_TYPES[n]))

# ------------------------------------------------------------------------------------------ hostile values
huge_ints = st.sampled_from([2**31, 2**32 - 1, 2**32, 2**53 + 1, 2**63 - 1, 2**63, 2**64 - 1, -(2**63), -1, 0])
nasty_floats = st.sampled_from([math.nan, math.inf, -math.inf, -0.0, 1e308, -1e308, 5e-324])
dtypes = st.sampled_from(["<f8", "<f4", "|u1", "<u2", "<i4", ">f8", "<f2", "|b1", "|O", "<U4", "V8", "<c16",
                          "f8,i4", "(2)f8", "<M8[s]", "bogus", "", "<f8\x00"])


@st.composite
def lying_array(draw: Any) -> dict[str, Any]:
    """An array map whose shape, dtype and byte length need not agree (or be sane)."""
    dims = draw(st.lists(st.one_of(st.integers(0, 6), huge_ints, st.just(True), st.just(1.5), st.just("3")),
                         max_size=draw(st.sampled_from([0, 1, 2, 3, 9]))))
    nbytes = draw(st.integers(0, 64))
    data = draw(st.sampled_from([b"\x00", b"\xff", b"\x7f\xf8"])) * nbytes
    if draw(st.booleans()):  # sometimes make byte length match the claimed shape for the dtype
        try:
            itemsize = np.dtype(draw(dtypes)).itemsize
            n = math.prod(d for d in dims if isinstance(d, int))
            if 0 <= n * itemsize <= 4096:
                data = b"\xff" * (n * itemsize)  # 0xff.. is NaN for floats
        except Exception:
            pass
    arr: dict[str, Any] = {"nd": draw(dtypes), "s": dims, "b": data}
    mutation = draw(st.integers(0, 6))
    if mutation == 0:
        arr.pop(draw(st.sampled_from(["nd", "s", "b"])))
    elif mutation == 1:
        arr["extra"] = 1
    elif mutation == 2:
        arr["b"] = draw(st.sampled_from(["text", 12, None, [1, 2]]))
    elif mutation == 3:
        arr["s"] = draw(st.sampled_from([3, None, "3", {"a": 1}]))
    return arr


def hostile_value(depth: int = 0) -> st.SearchStrategy[Any]:
    leaves = st.one_of(st.none(), st.booleans(), msgpack_ints, huge_ints, nasty_floats, finite, small_text,
                       st.binary(max_size=16), lying_array())
    if depth > 2:
        return leaves
    return st.one_of(leaves, st.lists(leaves, max_size=4),
                     st.dictionaries(small_text, leaves, max_size=4),
                     st.sampled_from(sorted(MESSAGE_TYPES)).flatmap(lambda n: hostile_wire(MESSAGE_TYPES[n],
                                                                                           depth + 1)))


@st.composite
def hostile_wire(draw: Any, cls: type[Message], depth: int = 0) -> dict[str, Any]:
    """The wire map of ``cls`` with fields replaced, dropped or added by hostile values."""
    valid = draw(valid_message(cls))
    raw: dict[str, Any] = msgpack.unpackb(valid.encode(), raw=False)
    names = [f.name for f in dataclasses.fields(cls)]  # type: ignore[arg-type]
    if draw(st.booleans()):  # one field hostile, the rest valid: decoding reaches that field's checks
        raw[draw(st.sampled_from(names))] = draw(hostile_value(depth + 1))
    else:
        for name in names:
            choice = draw(st.integers(0, 5))
            if choice == 0:
                raw[name] = draw(hostile_value(depth + 1))
            elif choice == 1:
                raw.pop(name, None)
    if draw(st.integers(0, 5)) == 0:
        raw[draw(small_text)] = draw(hostile_value(depth + 1))
    header = draw(st.sampled_from(["keep"] * 8 + ["v", "type"]))  # "keep" first: what shrinking favours
    if header == "v":
        raw["v"] = draw(st.one_of(msgpack_ints, small_text, st.none()))
    elif header == "type":
        raw["type"] = draw(st.one_of(small_text, msgpack_ints, st.sampled_from(sorted(MESSAGE_TYPES))))
    return raw


any_hostile_wire = st.sampled_from(sorted(MESSAGE_TYPES)).flatmap(lambda n: hostile_wire(MESSAGE_TYPES[n]))


def pack(obj: Any) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)
