"""Read docker compose files the way ``docker compose`` would, for tests on a machine without docker.

Covers what objscan's files use: the ``!override`` / ``!reset`` merge tags (Compose >= 2.24.4), variable
interpolation (``${VAR}``, ``${VAR:-default}``, ``${VAR:?message}`` which fails like compose does), and the
merge of an override file into a base file (mappings merged, ``command`` replaced, ``environment`` merged
by key, ``volumes`` by container path, ``ports``/``devices`` appended unless ``!override``).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml


class Override(list):
    """A sequence tagged ``!override``: replaces the base file's instead of adding to it."""


class ComposeInterpolationError(ValueError):
    """What ``docker compose`` prints and exits with for ``${VAR:?message}`` when VAR is unset or empty."""


class _Loader(yaml.SafeLoader):
    pass


_Loader.add_constructor("!override", lambda loader, node: Override(loader.construct_sequence(node, deep=True))
                        if isinstance(node, yaml.SequenceNode) else loader.construct_mapping(node, deep=True))
_Loader.add_constructor("!reset", lambda loader, node: None)


def load(path: Path) -> dict[str, Any]:
    return yaml.load(path.read_text(), Loader=_Loader)


_VAR = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)(?:(:?[-?])([^}]*))?\}")


def interpolate(value: Any, env: dict[str, str]) -> Any:
    """Substitute variables through a loaded file, as compose does before anything else."""
    if isinstance(value, dict):
        return {k: interpolate(v, env) for k, v in value.items()}
    if isinstance(value, list):
        out = [interpolate(v, env) for v in value]
        return Override(out) if isinstance(value, Override) else out
    if not isinstance(value, str):
        return value

    def sub(m: re.Match[str]) -> str:
        name, op, arg = m.group(1), m.group(2), m.group(3) or ""
        val = env.get(name)
        empty = val is None or (op is not None and op.startswith(":") and val == "")
        if op in (":?", "?") and empty:
            raise ComposeInterpolationError(f"required variable {name} is missing a value: {arg}")
        if op in (":-", "-") and empty:
            return arg
        return val or ""

    return _VAR.sub(sub, value)


def _volume_target(v: Any) -> str:
    if isinstance(v, dict):
        return v["target"]
    parts = str(v).split(":")
    return parts[1] if len(parts) > 1 else parts[0]


def merge(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    """``docker compose -f base -f override`` for the keys objscan's files use."""
    out = dict(base)
    services = {k: dict(v) for k, v in base.get("services", {}).items()}
    for name, over in override.get("services", {}).items():
        svc = services.setdefault(name, {})
        for key, value in over.items():
            if value is None:  # !reset
                svc.pop(key, None)
            elif isinstance(value, Override):
                svc[key] = list(value)
            elif key == "environment":
                svc[key] = {**svc.get(key, {}), **value}
            elif key == "volumes":
                merged = {_volume_target(v): v for v in svc.get(key, [])}
                merged.update({_volume_target(v): v for v in value})
                svc[key] = list(merged.values())
            elif key in ("ports", "devices", "device_cgroup_rules"):
                svc[key] = [*svc.get(key, []), *[v for v in value if v not in svc.get(key, [])]]
            else:
                svc[key] = value
    out["services"] = services
    return out


def started_by_default(compose: dict[str, Any]) -> list[str]:
    """Services ``docker compose up`` starts without ``--profile``."""
    return [n for n, s in compose["services"].items() if not s.get("profiles")]
