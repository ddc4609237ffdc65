"""``objscan certs``: a lab's certificate authority and one certificate per service identity.

Zenoh's mutual TLS identifies each process by the common name (CN) of its client certificate, and the
router's access-control policy (``deploy/zenoh-router-tls.json5``) grants rights by that CN: only the
``orchestrator`` may query the arm's ``move``/``gripper``/``stop`` keys, ``viewer`` may only subscribe.
So every identity gets its own key pair, signed by one lab CA that the router and every service trust.

Why ``openssl`` (the command): it is on every Linux box and in the Debian image, so the same command
works on the lab machine, in CI and in the container; no extra Python package is needed.

Layout written to ``OUT`` (default ``deploy/certs``)::

    ca.pem  ca.key            the lab CA (keep ca.key offline once the certificates are made)
    router.pem  router.key    the router's server certificate (SAN: zenoh-router, localhost, 127.0.0.1, ...)
    <identity>.pem <identity>.key   one client certificate per identity (CN = identity)

Run: ``python -m services.cli.cmd_certs --out deploy/certs`` (or ``objscan certs`` once wired).
"""

from __future__ import annotations

import argparse
import ipaddress
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from common.errors import ObjscanError

IDENTITIES = ("orchestrator", "camera", "arm", "sim", "registration", "grasp", "viewer", "operator", "ros2")
"""The identities of one cell (services, a read-only viewer, a person's CLI); each certificate's CN."""

ROUTER_NAMES = ("zenoh-router", "localhost", "127.0.0.1", "::1")
"""Names the router is reached by (compose service name, loopback); clients verify one of them."""


class CertError(ObjscanError):
    """Certificates could not be made (no openssl, bad name, openssl failed)."""

    code = "cert_failed"

    def __init__(self, message: str, *, code: str | None = None):
        super().__init__(message, code=code)


def _openssl() -> str:
    exe = shutil.which("openssl")
    if exe is None:
        raise CertError("the 'openssl' command is needed to make certificates (apt-get install openssl)")
    return exe


def _run(*args: str) -> None:
    out = subprocess.run([_openssl(), *args], capture_output=True, text=True, timeout=120)
    if out.returncode != 0:
        raise CertError(f"openssl {args[0]} failed: {out.stderr.strip()[-800:]}")


def _san(names: tuple[str, ...] | list[str]) -> str:
    parts = []
    for n in names:
        try:
            ipaddress.ip_address(n)
            parts.append(f"IP:{n}")
        except ValueError:
            parts.append(f"DNS:{n}")
    return ",".join(parts)


def _check_identity(name: str) -> None:
    if not name or not all(c.isalnum() or c in "-_." for c in name):
        raise CertError(f"identity {name!r} must be letters, digits, '-', '_' or '.'", code="bad_usage")


def make_ca(out: Path, *, days: int = 825, name: str = "objscan lab CA") -> tuple[Path, Path]:
    """A self-signed CA (EC P-256). Returns (certificate, key)."""
    out.mkdir(parents=True, exist_ok=True)
    cert, key = out / "ca.pem", out / "ca.key"
    _run("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
         "-keyout", str(key), "-out", str(cert), "-days", str(days), "-subj", f"/CN={name}",
         "-addext", "basicConstraints=critical,CA:TRUE", "-addext", "keyUsage=critical,keyCertSign,cRLSign")
    key.chmod(0o600)
    return cert, key


def make_leaf(out: Path, identity: str, *, ca_cert: Path, ca_key: Path, days: int = 825,
              dns: tuple[str, ...] | list[str] = ()) -> tuple[Path, Path]:
    """An EC key and a certificate with CN=``identity`` signed by the CA, usable as TLS client and server.

    ``dns`` adds subjectAltNames (the router needs the names clients dial; clients need none, but a
    SAN equal to the CN keeps strict verifiers happy). Returns (certificate, key).
    """
    _check_identity(identity)
    cert, key = out / f"{identity}.pem", out / f"{identity}.key"
    sans = list(dns) or [identity]
    with tempfile.TemporaryDirectory() as tmp:
        csr = Path(tmp) / "leaf.csr"
        ext = Path(tmp) / "leaf.ext"
        ext.write_text("basicConstraints=critical,CA:FALSE\n"
                       "keyUsage=critical,digitalSignature,keyEncipherment\n"
                       "extendedKeyUsage=serverAuth,clientAuth\n"
                       f"subjectAltName={_san(sans)}\n")
        _run("req", "-new", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
             "-keyout", str(key), "-out", str(csr), "-subj", f"/CN={identity}")
        _run("x509", "-req", "-in", str(csr), "-CA", str(ca_cert), "-CAkey", str(ca_key), "-CAcreateserial",
             "-out", str(cert), "-days", str(days), "-extfile", str(ext))
    key.chmod(0o600)
    return cert, key


def generate_lab_certs(out: Path, identities: tuple[str, ...] | list[str] = IDENTITIES, *,
                       router_names: tuple[str, ...] | list[str] = ROUTER_NAMES, days: int = 825,
                       force: bool = False) -> dict[str, Path]:
    """Make the CA (unless one exists), the router's certificate and one per identity.

    An existing CA is reused so adding an identity later does not invalidate the others; ``force``
    starts over. Returns a map name → certificate path (``ca``, ``router`` and each identity).
    """
    out = Path(out)
    if force and out.exists():
        for p in out.glob("*"):
            if p.suffix in (".pem", ".key", ".srl"):
                p.unlink()
    ca_cert, ca_key = out / "ca.pem", out / "ca.key"
    if not (ca_cert.is_file() and ca_key.is_file()):
        ca_cert, ca_key = make_ca(out, days=days)
    made = {"ca": ca_cert}
    made["router"] = make_leaf(out, "router", ca_cert=ca_cert, ca_key=ca_key, days=days,
                               dns=list(router_names))[0]
    for ident in identities:
        made[ident] = make_leaf(out, ident, ca_cert=ca_cert, ca_key=ca_key, days=days)[0]
    return made


def certificate_subject(cert: Path) -> str:
    """The subject line of a certificate (for checks and ``--show``)."""
    out = subprocess.run([_openssl(), "x509", "-in", str(cert), "-noout", "-subject"], capture_output=True,
                         text=True, timeout=30)
    if out.returncode != 0:
        raise CertError(f"cannot read {cert}: {out.stderr.strip()}")
    return out.stdout.strip()


# ------------------------------------------------------------------------------------------- CLI
def register(sub) -> None:  # noqa: ANN001 - argparse subparsers
    p = sub.add_parser("certs", help="make a lab CA and one TLS certificate per service identity",
                       description=__doc__.split("\n\n")[1] if __doc__ else None)
    _add_args(p)
    p.set_defaults(func=run)


def _add_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="deploy/certs", help="folder for the certificates (default: %(default)s)")
    p.add_argument("--identity", action="append", dest="identities",
                   help=f"identity to certify (repeatable; default: {', '.join(IDENTITIES)})")
    p.add_argument("--router-name", action="append", dest="router_names",
                   help="extra DNS name or IP clients use to reach the router (repeatable)")
    p.add_argument("--days", type=int, default=825, help="validity in days (default: %(default)s)")
    p.add_argument("--force", action="store_true", help="discard an existing CA and start over")
    p.add_argument("--json", dest="json_output", action="store_true",
                   help="print one JSON object {name: certificate path} (or the error) instead of the list")


def run(args) -> int:  # noqa: ANN001
    made = generate_lab_certs(Path(args.out), args.identities or IDENTITIES,
                              router_names=[*ROUTER_NAMES, *(args.router_names or [])], days=args.days,
                              force=args.force)
    if args.json_output:
        print(json.dumps({name: str(cert) for name, cert in made.items()}))
        return 0
    for name, cert in made.items():
        print(f"{name:13s} {cert}")
    print(f"keep {Path(args.out) / 'ca.key'} offline; give each machine only ca.pem and its own .pem/.key")
    return 0


def main(argv: list[str] | None = None) -> int:
    from services.cli.main import main as objscan

    return objscan(["certs", *(argv if argv is not None else sys.argv[1:])])


if __name__ == "__main__":
    sys.exit(main())
