"""A Zenoh router started from the shipped ``deploy/zenoh-router-tls.json5``, for tests on loopback.

Only the certificate folder and the listen endpoint change (the docker paths ``/certs/...`` do not exist
here); the access-control policy is used exactly as shipped, so the tests test what a lab deploys.
Run: ``python -m tests.security.tls_router --certs DIR --listen tls/127.0.0.1:PORT``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import zenoh

from common.router import serve

REPO = Path(__file__).resolve().parents[2]
ROUTER_CONFIG = REPO / "deploy" / "zenoh-router-tls.json5"


def tls_router_config(certs: Path, listen: list[str], config_file: Path = ROUTER_CONFIG) -> zenoh.Config:
    """The shipped router config with certificates from ``certs`` and the given listen endpoints."""
    conf = zenoh.Config.from_file(str(config_file))
    conf.insert_json5("listen/endpoints", json.dumps(listen))
    conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(certs / "ca.pem")))
    conf.insert_json5("transport/link/tls/listen_certificate", json.dumps(str(certs / "router.pem")))
    conf.insert_json5("transport/link/tls/listen_private_key", json.dumps(str(certs / "router.key")))
    return conf


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description="objscan TLS + ACL router for tests")
    p.add_argument("--certs", required=True, help="folder made by objscan certs")
    p.add_argument("--listen", required=True, help="comma-separated tls/ endpoints")
    p.add_argument("--config", default=str(ROUTER_CONFIG))
    args = p.parse_args(argv)
    serve(tls_router_config(Path(args.certs), [e for e in args.listen.split(",") if e], Path(args.config)),
          f"zenoh TLS router listening on {args.listen}")


if __name__ == "__main__":
    main()
