"""A Zenoh router in Python: the embedded default (``objscan up``).

Docker deployments use the official ``eclipse/zenoh`` router instead; both speak the same protocol, so
services cannot tell them apart. Run: ``python -m common.router --listen tcp/127.0.0.1:7447``.
"""

from __future__ import annotations

import argparse
import json
import signal
import threading

import zenoh

from common.zenoh_config import DEFAULT_CONNECT


def router_config(listen: list[str]) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", json.dumps(listen))
    return conf


def serve(conf: zenoh.Config, banner: str) -> None:
    """Run a router with ``conf`` until SIGINT/SIGTERM, then close its session."""
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    session = zenoh.open(conf)
    print(banner, flush=True)
    try:
        stop.wait()
    finally:
        session.close()


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description="objscan's embedded Zenoh router")
    p.add_argument("--listen", default=DEFAULT_CONNECT, help="comma-separated endpoints (default %(default)s)")
    args = p.parse_args(argv)
    serve(router_config([e for e in args.listen.split(",") if e]), f"zenoh router listening on {args.listen}")


if __name__ == "__main__":
    main()
