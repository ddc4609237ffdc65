"""``objscan models``: the model library — list, show, export, delete, and find by a partial view.

``--library DIR`` (default ``models/``) picks the library folder; it is created on first use. ``--json``
prints machine-readable output instead of tables. A failure is the CLI's one line (``services/cli/outcome.py``):
an unknown or ambiguous id, a missing file or a folder that is not a library is bad input (exit 2).
"""

from __future__ import annotations

import json

from rich.console import Console
from rich.table import Table

from services.cli.outcome import require_path

DEFAULT_LIBRARY = "models"


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("models", help="the model library: list, show, export, delete, find by a partial view")
    p.add_argument("--library", default=DEFAULT_LIBRARY, help="library folder (default: %(default)s/)")
    p.add_argument("--json", dest="json_output", action="store_true", help="print JSON instead of tables")
    ops = p.add_subparsers(dest="models_command", metavar="ACTION", required=True)
    ops.add_parser("list", help="every stored model").add_argument("--object", help="only models of this object")
    ops.add_parser("show", help="one model's metadata").add_argument("id", help="model id (a unique prefix is enough)")
    e = ops.add_parser("export", help="copy a model out (DEST.ply, or a folder)")
    e.add_argument("id", help="model id (a unique prefix is enough)")
    e.add_argument("dest", help="where to copy it: a .ply file, or a folder for the model's files")
    ops.add_parser("delete", help="remove a model").add_argument("id", help="model id (a unique prefix is enough)")
    f = ops.add_parser("find", help="best-matching models for a partial view (point cloud file)")
    f.add_argument("cloud", help="PLY/PCD of the partial view (colors help: shapes alike differ by print)")
    f.add_argument("--top", type=int, default=3, help="how many matches to print (default: %(default)s)")
    f.add_argument("--shortlist", type=int, default=None,
                   help="models kept after the descriptor stage for the full match (default: the library's)")
    f.add_argument("--not-upright", action="store_true",
                   help="the view is not in a z-up frame: rely on feature matching only (no yaw search)")
    p.set_defaults(func=run)


def run(args) -> int:  # noqa: ANN001
    from services.library import FindConfig, ModelLibrary

    console = Console()
    as_json = args.json_output
    cmd = args.models_command
    if cmd == "find":  # before the library is opened (or made): a missing view is bad input
        require_path(args.cloud, "partial view")
    lib = ModelLibrary(args.library)
    if cmd == "list":
        rows = [e.summary() for e in lib.list(args.object)]
        if as_json:
            print(json.dumps(rows, indent=2))
        elif not rows:
            console.print(f"no models in {lib.root}")
        else:
            _table(console, f"models in {lib.root}", rows,
                   ["id", "object", "created", "points", "configuration", "chamfer_mm", "mesh"])
    elif cmd == "show":
        entry = lib.get(args.id)
        data = {"id": entry.id, "path": str(entry.path), "points": entry.points, **entry.metadata.to_dict()}
        desc = data.get("descriptor", {})
        if not as_json and "whole" in desc:
            desc["whole"] = f"<{len(desc['whole'])} values>"
        print(json.dumps(data, indent=2, default=str))
    elif cmd == "export":
        files = lib.export(args.id, args.dest)
        print(json.dumps([str(f) for f in files]) if as_json else "\n".join(f"wrote {f}" for f in files))
    elif cmd == "delete":
        gone = lib.delete(args.id)
        print(json.dumps({"deleted": gone}) if as_json else f"deleted {gone}")
    elif cmd == "find":
        cfg = FindConfig()
        if args.shortlist is not None or args.not_upright:
            from dataclasses import replace

            cfg = replace(cfg, shortlist=args.shortlist or cfg.shortlist, upright=not args.not_upright)
        matches = lib.find(args.cloud, top_k=args.top, config=cfg)
        rows = [{"rank": i + 1, "id": m.id, "object": m.detail["object"], "score": round(m.score, 4),
                 "fitness": m.detail["fitness"], "coverage": m.detail["coverage"], "color": m.detail["color"],
                 "descriptor_rank": m.detail["descriptor_rank"]} for i, m in enumerate(matches)]
        if as_json:
            print(json.dumps([{"id": m.id, "score": m.score, "detail": m.detail} for m in matches], indent=2))
        elif not rows:
            console.print(f"no models in {lib.root}")
        else:
            _table(console, f"best matches for {args.cloud}", rows, list(rows[0]))
    return 0


def _table(console: Console, title: str, rows: list[dict], columns: list[str]) -> None:
    table = Table(title=title)
    for c in columns:
        table.add_column(c)
    for r in rows:
        table.add_row(*("" if r.get(c) is None else str(r.get(c)) for c in columns))
    console.print(table)
