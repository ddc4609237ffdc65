"""``objscan bench NAME [--json PATH]``: run a benchmark from ``bench/``, print a table, write JSON."""

from __future__ import annotations

import importlib
import inspect
import json
import pkgutil
from pathlib import Path

import bench
from bench.report import print_figures
from common.atomic import atomic_write_bytes
from services.cli.outcome import BadUsage


def available() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(bench.__path__) if not m.name.startswith("_")
                  and m.name not in ("report", "frame_server", "harsh_set", "multiway_peer"))


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("bench", help="run a benchmark and print its figures",
                       description=f"Benchmarks: {', '.join(available())}. Figures are measured against "
                                   "baselines in the same run; see BENCHMARKS.md.")
    p.add_argument("name", choices=available(), help="the benchmark to run (one of the list above)")
    p.add_argument("--json", metavar="PATH",
                   help="write the figures as one JSON object to this file (the table still goes to stdout)")
    p.add_argument("--quick", action="store_true", help="a smaller run for a fast check")
    p.add_argument("--set", dest="object_set", choices=["harsh", "realistic", "all"], default=None,
                   help="reconstruct: which object set (harsh primitives, realistic HOPE objects; default all)")
    p.add_argument("--arm-backend", choices=["sim", "dynamixel"],
                   help="the arm backend, for benchmarks that take one (estop; default: sim)")
    p.add_argument("--emulate-bus", action="store_true",
                   help="dynamixel: the emulated PAPRAS bus (the only bus a benchmark drives)")
    p.add_argument("--runs", type=int, metavar="N",
                   help="completion: runs per family (default 4; --quick: 1)")
    p.add_argument("--seed", type=int, metavar="S",
                   help="completion: the seed the shapes and the twin's physics are drawn from (default 3)")
    p.set_defaults(func=run)


def _arm_options(module, args) -> dict:  # noqa: ANN001
    """``--arm-backend``/``--emulate-bus`` for a benchmark whose ``run`` takes them; refused for others."""
    wanted = {k: v for k in ("arm_backend", "emulate_bus") if (v := getattr(args, k, None))}
    accepted = inspect.signature(module.run).parameters
    refused = [k for k in wanted if k not in accepted]
    if refused:
        raise BadUsage(f"{args.name} takes no {', '.join('--' + k.replace('_', '-') for k in refused)}")
    return wanted


def _draw_options(module, args) -> dict:  # noqa: ANN001
    """``--runs``/``--seed`` for a benchmark whose ``run`` takes them (completion); refused for others."""
    wanted = {k: v for k in ("runs", "seed") if (v := getattr(args, k, None)) is not None}
    accepted = inspect.signature(module.run).parameters
    refused = [k for k in wanted if k not in accepted]
    if refused:
        raise BadUsage(f"{args.name} takes no {', '.join('--' + k for k in refused)}")
    if wanted.get("runs", 1) < 1:
        raise BadUsage("--runs must be at least 1")
    return wanted


def run(args) -> int:  # noqa: ANN001
    module = importlib.import_module(f"bench.{args.name}")
    kwargs = {"quick": args.quick, **_arm_options(module, args), **_draw_options(module, args)}
    if getattr(args, "object_set", None):
        if "object_set" not in inspect.signature(module.run).parameters:
            raise BadUsage(f"{args.name} has no object sets (--set is for reconstruct)")
        kwargs["object_set"] = args.object_set
    figures = module.run(**kwargs)
    print_figures(args.name, figures)
    if args.json:
        atomic_write_bytes(Path(args.json), json.dumps(figures, indent=2, default=float).encode())
        print(f"wrote {args.json}")
    return 0
