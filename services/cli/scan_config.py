"""The acquisition config ``objscan scan`` sends: the config file (``--config``), then the flags over it.

Why one place: the orchestrator validates every config it is sent (``AcquisitionConfig.from_dict``: types,
ranges, the arm's reach, unknown keys refused); building the same object here first means a bad file or flag
is refused before any service starts, with the same message naming the key, and the orchestrator receives
exactly what was checked. Precedence: ``AcquisitionConfig`` defaults < the CLI's own defaults
(``CLI_DEFAULTS``: MuJoCo physics) < the file < the flags given on the command line.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import yaml

from services.cli.outcome import BadUsage, require_path
from services.orchestrator.config import UP_AXES, AcquisitionConfig, ConfigError
from services.sim.demo_objects import DEFAULT_OBJECT

CLI_DEFAULTS: dict[str, Any] = {"physics": "mujoco", "object": DEFAULT_OBJECT}
"""Where the command's default differs from the config's: a scan from the CLI grasps with contact physics, and
scans a demo object that ships with objscan (a bare checkout has no other)."""

FLAG_KEYS = {  # argparse dest -> config key, for the flags that set a config key
    "object": "object", "views": "views", "profile": "profile", "seed": "seed", "physics": "physics",
    "width": "width", "height": "height", "turn_deg": "turn_deg", "workspace_center": "workspace_center",
    "scale": "object_scale", "up_axis": "object_up_axis",
}


def workspace_center(text: str) -> tuple[float, float]:
    """``--workspace-center X,Y`` (metres): two numbers; whether the arm reaches them is the config's check."""
    parts = [p.strip() for p in text.split(",")]
    try:
        if len(parts) != 2:
            raise ValueError
        return float(parts[0]), float(parts[1])
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y in metres (e.g. 0.6,0.0), got {text!r}") from None


def add_config_args(p: argparse.ArgumentParser) -> None:
    """The flags that set acquisition config keys (default None: the file's value, else the config's default)."""
    d = AcquisitionConfig()
    p.add_argument("--config", metavar="FILE.yaml",
                   help="acquisition config file: the keys of the orchestrator's config (docs/orchestrator.md); "
                        "flags given here override it")
    p.add_argument("--object", help="sim: a demo object (carton, can, flat_box), a HOPE name, or a mesh file or "
                                    f"folder (default: {CLI_DEFAULTS['object']})")
    p.add_argument("--scale", type=float,
                   help="sim: the mesh's units in metres, e.g. 0.001 for a mesh in millimetres (default: the "
                        "file's own: HOPE 0.01, other meshes 1)")
    p.add_argument("--up-axis", choices=UP_AXES, metavar="{x,y,z}",
                   help="sim: the mesh's upright axis, x, y or z (or -x, -y, -z) (default: HOPE y, other meshes z)")
    p.add_argument("--views", type=int, help=f"views to acquire, turning the object between them (default: {d.views})")
    p.add_argument("--turn-deg", type=float, metavar="D",
                   help=f"degrees the object turns between views, in (0, 180] (default: {d.turn_deg:g})")
    p.add_argument("--workspace-center", type=workspace_center, metavar="X,Y",
                   help="where the object stands on the table, metres in the arm's base frame; must be within "
                        f"the arm's reach (default: {d.workspace_center[0]:g},{d.workspace_center[1]:g})")
    p.add_argument("--profile", choices=["ideal", "hand-turned", "realistic", "robot-turned"],
                   help=f"sim error profile (default: {d.profile})")
    p.add_argument("--seed", type=int, help=f"sim: seed of the profile's drawn errors (default: {d.seed})")
    p.add_argument("--physics", choices=["mujoco", "geometric"],
                   help="sim: grasp, lift and set-down by MuJoCo contact physics, or the fast geometric checker "
                        f"with drawn errors (default: {CLI_DEFAULTS['physics']})")
    p.add_argument("--width", type=int, help=f"camera image width in pixels (default: {d.width})")
    p.add_argument("--height", type=int, help=f"camera image height in pixels (default: {d.height})")


def load_config_file(path: str | Path) -> dict[str, Any]:
    """The map in a YAML (or JSON) config file; a missing file, bad YAML or a non-map is bad input."""
    p = require_path(path, "config file")
    try:
        data = yaml.safe_load(p.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise BadUsage(f"cannot read config file {path}: {exc}", detail={"path": str(path)}) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        why = getattr(exc, "problem", None) or " ".join(str(exc).split())
        raise ConfigError(f"{path}: not valid YAML ({where}{why})", detail={"path": str(path)}) from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: must hold a map of config keys, got {type(data).__name__}",
                          detail={"path": str(path)})
    return data


def scan_config(args: argparse.Namespace) -> AcquisitionConfig:
    """The validated config of this scan: defaults, then ``--config``, then the flags given."""
    data: dict[str, Any] = dict(CLI_DEFAULTS)
    if getattr(args, "config", None):
        from_file = load_config_file(args.config)
        try:
            AcquisitionConfig.from_dict(dict(from_file))  # the file alone first: its errors name the file
        except ConfigError as exc:
            raise ConfigError(f"{args.config}: {exc.message}", detail={**exc.detail, "path": str(args.config)}
                              ) from None
        data.update(from_file)
    for dest, key in FLAG_KEYS.items():
        value = getattr(args, dest, None)
        if value is not None:
            data[key] = list(value) if isinstance(value, tuple) else value
    if getattr(args, "force_first_slip", False):
        data["force_first_slip"] = True
    if getattr(args, "no_incremental", False):
        data["incremental"] = False
    return AcquisitionConfig.from_dict(data)
