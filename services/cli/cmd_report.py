"""``objscan report SESSION_DIR [--out FILE]``: one self-contained HTML page about an acquisition."""

from __future__ import annotations

import sys

from common.errors import ObjscanError


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("report", help="write a self-contained HTML report of a session folder")
    p.add_argument("session", help="session folder (as written by 'objscan scan')")
    p.add_argument("--out", default=None, help="HTML file to write (default: SESSION/report.html)")
    p.set_defaults(func=run)


def run(args) -> int:  # noqa: ANN001
    from services.report import build_report

    try:
        path = build_report(args.session, args.out)
    except ObjscanError as exc:
        print(f"error [{exc.code}]: {exc.message}", file=sys.stderr)
        return 2
    print(f"wrote {path}")
    return 0
