"""``objscan report SESSION_DIR [--out FILE]``: one self-contained HTML page about an acquisition."""

from __future__ import annotations

from services.cli.outcome import print_json, require_path


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("report", help="write a self-contained HTML report of a session folder")
    p.add_argument("session", help="session folder (as written by 'objscan scan')")
    p.add_argument("--out", default=None, help="HTML file to write (default: SESSION/report.html)")
    p.add_argument("--json", dest="json_output", action="store_true",
                   help="print one JSON object ({\"report\": FILE}, or the error) instead of the line")
    p.set_defaults(func=run)


def run(args) -> int:  # noqa: ANN001
    require_path(args.session, "session folder")  # before the heavy imports: a missing folder is said at once
    from services.report import build_report

    path = build_report(args.session, args.out)
    if args.json_output:
        print_json({"report": str(path)})
    else:
        print(f"wrote {path}")
    return 0
