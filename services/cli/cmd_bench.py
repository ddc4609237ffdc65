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


def available() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(bench.__path__) if not m.name.startswith("_")
                  and m.name not in ("report", "frame_server", "harsh_set", "multiway_peer"))


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("bench", help="run a benchmark and print its figures",
                       description=f"Benchmarks: {', '.join(available())}. Figures are measured against "
                                   "baselines in the same run; see BENCHMARKS.md.")
    p.add_argument("name", choices=available())
    p.add_argument("--json", help="write the figures as one JSON object to this path")
    p.add_argument("--quick", action="store_true", help="a smaller run for a fast check")
    p.add_argument("--set", dest="object_set", choices=["harsh", "realistic", "all"], default=None,
                   help="reconstruct: which object set (harsh primitives, realistic HOPE objects; default all)")
    p.set_defaults(func=run)


def run(args) -> int:  # noqa: ANN001
    module = importlib.import_module(f"bench.{args.name}")
    kwargs = {"quick": args.quick}
    if getattr(args, "object_set", None):
        if "object_set" not in inspect.signature(module.run).parameters:
            print(f"objscan bench {args.name} has no object sets (--set is for reconstruct)")
            return 2
        kwargs["object_set"] = args.object_set
    figures = module.run(**kwargs)
    print_figures(args.name, figures)
    if args.json:
        atomic_write_bytes(Path(args.json), json.dumps(figures, indent=2, default=float).encode())
        print(f"wrote {args.json}")
    return 0
