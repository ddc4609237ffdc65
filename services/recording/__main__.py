"""``python -m services.recording info|recover``: look into a recording, or make a crashed one complete.

- ``info SESSION_DIR_OR_MCAP``: parts, truncation, metadata, messages per topic;
- ``recover IN.mcap OUT.mcap``: rewrite a file a killed writer left without summary/footer.
"""

from __future__ import annotations

import argparse
import json
import sys

from common.errors import ObjscanError
from services.recording.reader import read_recording, recover


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m services.recording")
    sub = p.add_subparsers(dest="cmd", required=True)
    info = sub.add_parser("info", help="what a recording holds")
    info.add_argument("source")
    rec = sub.add_parser("recover", help="rewrite a truncated recording into a complete MCAP file")
    rec.add_argument("source")
    rec.add_argument("out")
    args = p.parse_args(argv)
    try:
        if args.cmd == "recover":
            print(json.dumps(recover(args.source, args.out)))
            return 0
        r = read_recording(args.source)
    except ObjscanError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"parts: {', '.join(str(p) for p in r.paths)}")
    print(f"truncated (killed writer; readable, see recover): {[str(p) for p in r.truncated] or 'none'}")
    s = r.metadata.get("session", {})
    print(f"session: object={s.get('object')} profile={s.get('profile')} seed={s.get('seed')} views={s.get('views')}")
    print(f"exchanges: {len(r.exchanges)}; closed cleanly: {'closed' in r.metadata}")
    width = max((len(t) for t in r.counts), default=10)
    for topic, n in sorted(r.counts.items()):
        ch = r.channels.get(topic, {})
        print(f"  {topic:<{width}}  {n:>7}  {ch.get('schema') or ch.get('encoding')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
