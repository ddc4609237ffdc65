"""A backend's own options: declared once on its options dataclass, given as ``--option KEY=VALUE``.

Why: the camera and arm services are generic; which backends exist is said only by their registries
(``services/camera/registry.py``, ``services/arm/drivers/registry.py``). A backend that needs a serial port or
a session folder declares it here, with its type, default, help and environment variable, and the service
takes it as ``--option KEY=VALUE`` without a flag of its own. A wrong key or value is a typed error that names
the backend's valid keys, before any hardware is touched.

    @dataclass(frozen=True)
    class ReplayOptions:
        session: str = option("", "the session folder to serve frames from")

``parse_options(ReplayOptions, {"session": "DIR"}, backend="replay", error=CameraConfigError)``.
"""

from __future__ import annotations

import dataclasses
import os
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from common.errors import ObjscanError

_TRUE, _FALSE = ("1", "true", "yes", "on"), ("0", "false", "no", "off")


def option(default: Any, help: str, *, env: str | None = None) -> Any:  # noqa: A002 - argparse's word
    """A field of a backend's options dataclass: its default, what it means, and the environment variable
    that sets it when the command line does not."""
    return dataclasses.field(default=default, metadata={"help": help, "env": env})


@dataclass(frozen=True)
class OptionSpec:
    """One declared option: name, type (``int``, ``float``, ``bool``, ``str``; optional: ``None`` allowed),
    default, help and environment variable."""

    name: str
    type: type
    optional: bool
    default: Any
    help: str
    env: str | None

    def describe(self) -> str:
        """``name (type, default: ...; env VAR): help``, for ``--help`` and the docs."""
        kind = self.type.__name__ + (" or none" if self.optional else "")
        env = f"; env {self.env}" if self.env else ""
        return f"{self.name} ({kind}, default: {self.default!r}{env}): {self.help}"


def option_specs(cls: type) -> dict[str, OptionSpec]:
    """The options ``cls`` (a dataclass of ``option`` fields) declares, by name."""
    hints = typing.get_type_hints(cls)
    out = {}
    for f in dataclasses.fields(cls):
        kind, optional = hints[f.name], False
        args = typing.get_args(kind)
        if typing.get_origin(kind) in (typing.Union, types.UnionType) and type(None) in args:
            optional, kind = True, next(a for a in args if a is not type(None))
        out[f.name] = OptionSpec(f.name, kind, optional, f.default, f.metadata.get("help", ""),
                                 f.metadata.get("env"))
    return out


def _convert(spec: OptionSpec, value: Any, backend: str, error: type[ObjscanError]) -> Any:
    if spec.optional and (value is None or isinstance(value, str) and value.strip().lower() in ("", "none")):
        return None
    if isinstance(value, spec.type) and not (spec.type is int and isinstance(value, bool)):
        return value
    text = str(value).strip()
    try:
        if spec.type is bool:
            if text.lower() in _TRUE:
                return True
            if text.lower() in _FALSE:
                return False
            raise ValueError(text)
        if spec.type is str:
            return text
        return spec.type(text)
    except (TypeError, ValueError):
        raise error(f"{backend} option {spec.name}={value!r} is not a {spec.type.__name__}", code="bad_option",
                    detail={"backend": backend, "key": spec.name, "value": str(value),
                            "type": spec.type.__name__}) from None


def parse_options(cls: type, given: Mapping[str, Any], *, backend: str, error: type[ObjscanError],
                  environ: Mapping[str, str] | None = None) -> Any:
    """An instance of ``cls`` from ``given`` (strings from ``--option``, or values of the right type); an
    option not given takes its environment variable, else its default. An unknown key or a value of the
    wrong type raises ``error`` (code ``unknown_option`` / ``bad_option``) naming the backend's valid keys."""
    specs = option_specs(cls)
    unknown = sorted(set(given) - set(specs))
    if unknown:
        valid = sorted(specs)
        raise error(f"{backend} has no option {', '.join(unknown)}; its options: {', '.join(valid) or 'none'}",
                    code="unknown_option", detail={"backend": backend, "unknown": unknown, "valid": valid})
    env = os.environ if environ is None else environ
    values = {}
    for name, spec in specs.items():
        if name in given:
            values[name] = _convert(spec, given[name], backend, error)
        elif spec.env and env.get(spec.env):
            values[name] = _convert(spec, env[spec.env], backend, error)
    return cls(**values)


def option_pair(text: str) -> tuple[str, str]:
    """``KEY=VALUE`` from the command line (``--option``) -> (key, value); ``-`` in the key reads as ``_``.
    For argparse's ``type=``: a malformed pair is a usage error."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise ValueError(f"expected KEY=VALUE, got {text!r}")
    return key.strip().replace("-", "_"), value


def options_help(cls: type) -> str:
    """One line per option of ``cls``, for ``--help``."""
    return "; ".join(spec.describe() for spec in option_specs(cls).values())
