"""Zenoh session configuration: one optional file plus environment overrides.

The same service binary runs in a test on loopback, as one of many processes on the lab's compute box,
or on another machine against a router: only these settings change.

Environment variables (all optional):

| variable | meaning | default |
|---|---|---|
| ``OBJSCAN_ZENOH_CONFIG`` | a zenoh JSON5 config file, applied first | none |
| ``OBJSCAN_ZENOH_MODE`` | ``client`` (through a router) or ``peer`` | ``client`` |
| ``OBJSCAN_ZENOH_CONNECT`` | comma-separated endpoints, e.g. ``tcp/127.0.0.1:7447`` | ``tcp/127.0.0.1:7447`` |
| ``OBJSCAN_ZENOH_LISTEN`` | comma-separated endpoints to listen on | none (peers listen on ``tcp/127.0.0.1:0``) |
| ``OBJSCAN_ZENOH_MULTICAST`` | ``1`` to enable multicast scouting | ``0`` |
| ``OBJSCAN_ZENOH_CONNECT_TIMEOUT_MS`` | how long a client waits for its router at start (-1: forever) | ``10000`` |
| ``OBJSCAN_ZENOH_TLS_CA`` | CA certificate (PEM) that signed the router's and every service's certificate | none |
| ``OBJSCAN_ZENOH_TLS_CERT`` | this process's certificate (PEM); its CN is the identity the router's ACL sees | none |
| ``OBJSCAN_ZENOH_TLS_KEY`` | this process's private key (PEM) | none |

TLS: with ``OBJSCAN_ZENOH_TLS_CA`` set, ``tls/...`` endpoints verify the router against that CA; with the
certificate and key set too, the process authenticates itself (mutual TLS). See docs/security.md.

Why clients by default: in Zenoh 1.x peers route only over direct links (``peer_to_peer``), so a peer that
has not yet linked to every other peer misses some of them; clients send everything through the router,
which sees all. Peers remain available (``OBJSCAN_ZENOH_MODE=peer``) for a flat network without a router.
"""

from __future__ import annotations

import json
import os
import socket
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import zenoh

from common.errors import RouterUnreachable

DEFAULT_ROUTER_PORT = 7447
DEFAULT_CONNECT = f"tcp/127.0.0.1:{DEFAULT_ROUTER_PORT}"


def _split(value: str | None) -> list[str]:
    return [v.strip() for v in value.split(",") if v.strip()] if value else []


@dataclass
class ZenohSettings:
    """How a process joins the Zenoh network."""

    mode: str = "client"
    connect: list[str] = field(default_factory=lambda: [DEFAULT_CONNECT])
    listen: list[str] = field(default_factory=list)
    multicast_scouting: bool = False
    config_file: str | None = None
    connect_timeout_ms: int = 10000
    tls: TlsSettings | None = None

    @classmethod
    def from_env(cls, env: dict[str, str] | None = None) -> ZenohSettings:
        env = dict(os.environ if env is None else env)
        s = cls()
        if env.get("OBJSCAN_ZENOH_MODE"):
            s.mode = env["OBJSCAN_ZENOH_MODE"]
        if "OBJSCAN_ZENOH_CONNECT" in env:
            s.connect = _split(env["OBJSCAN_ZENOH_CONNECT"])
        if "OBJSCAN_ZENOH_LISTEN" in env:
            s.listen = _split(env["OBJSCAN_ZENOH_LISTEN"])
        if "OBJSCAN_ZENOH_MULTICAST" in env:
            s.multicast_scouting = env["OBJSCAN_ZENOH_MULTICAST"].strip().lower() in ("1", "true", "yes", "on")
        if env.get("OBJSCAN_ZENOH_CONFIG"):
            s.config_file = env["OBJSCAN_ZENOH_CONFIG"]
        if env.get("OBJSCAN_ZENOH_CONNECT_TIMEOUT_MS"):
            s.connect_timeout_ms = int(env["OBJSCAN_ZENOH_CONNECT_TIMEOUT_MS"])
        s.tls = TlsSettings.from_env(env)
        return s

    def with_overrides(self, *, mode: str | None = None, connect: list[str] | None = None,
                       listen: list[str] | None = None) -> ZenohSettings:
        out = replace(self)
        if mode:
            out.mode = mode
        if connect is not None:
            out.connect = connect
        if listen is not None:
            out.listen = listen
        return out

    def to_env(self) -> dict[str, str]:
        """The environment a child process needs to join the same network."""
        env = {
            "OBJSCAN_ZENOH_MODE": self.mode,
            "OBJSCAN_ZENOH_CONNECT": ",".join(self.connect),
            "OBJSCAN_ZENOH_MULTICAST": "1" if self.multicast_scouting else "0",
            "OBJSCAN_ZENOH_CONNECT_TIMEOUT_MS": str(self.connect_timeout_ms),
        }
        if self.listen:
            env["OBJSCAN_ZENOH_LISTEN"] = ",".join(self.listen)
        if self.config_file:
            env["OBJSCAN_ZENOH_CONFIG"] = self.config_file
        if self.tls is not None:
            env.update(self.tls.to_env())
        return env

    def to_zenoh(self) -> zenoh.Config:
        if self.config_file:
            path = Path(self.config_file)
            if not path.is_file():
                raise FileNotFoundError(f"zenoh config file {path} does not exist")
            conf = zenoh.Config.from_file(str(path))
        else:
            conf = zenoh.Config()
        conf.insert_json5("mode", json.dumps(self.mode))
        conf.insert_json5("scouting/multicast/enabled", "true" if self.multicast_scouting else "false")
        if self.connect:
            conf.insert_json5("connect/endpoints", json.dumps(self.connect))
            if self.mode == "client":  # -1 waits for the router forever (compose start-up order)
                conf.insert_json5("connect/timeout_ms", str(self.connect_timeout_ms))
        listen = self.listen or (["tcp/127.0.0.1:0"] if self.mode == "peer" and not self.config_file else [])
        if listen:
            conf.insert_json5("listen/endpoints", json.dumps(listen))
        if self.tls is not None:
            self.tls.apply(conf)
        return conf


# ------------------------------------------------------------------------------------------------- TLS
@dataclass
class TlsSettings:
    """Mutual TLS for ``tls/...`` endpoints (see docs/security.md).

    ``ca`` alone: the process checks the router's certificate but shows none itself (a router with
    ``enable_mtls`` refuses it). ``ca`` + ``cert`` + ``key``: mutual authentication; the certificate's
    CN is the identity the router's access-control policy grants rights to.
    """

    ca: str
    cert: str | None = None
    key: str | None = None

    @classmethod
    def from_env(cls, env: dict[str, str]) -> TlsSettings | None:
        ca = env.get("OBJSCAN_ZENOH_TLS_CA")
        if not ca:
            return None
        cert, key = env.get("OBJSCAN_ZENOH_TLS_CERT") or None, env.get("OBJSCAN_ZENOH_TLS_KEY") or None
        if (cert is None) != (key is None):
            raise ValueError("OBJSCAN_ZENOH_TLS_CERT and OBJSCAN_ZENOH_TLS_KEY must be set together")
        return cls(ca=ca, cert=cert, key=key)

    def to_env(self) -> dict[str, str]:
        env = {"OBJSCAN_ZENOH_TLS_CA": self.ca}
        if self.cert and self.key:
            env.update(OBJSCAN_ZENOH_TLS_CERT=self.cert, OBJSCAN_ZENOH_TLS_KEY=self.key)
        return env

    def apply(self, conf: zenoh.Config) -> None:
        """Set ``transport/link/tls`` (files must exist: a typo fails here, not as a silent plain link)."""
        for path in (self.ca, self.cert, self.key):
            if path is not None and not Path(path).is_file():
                raise FileNotFoundError(f"TLS file {path} does not exist")
        tls: dict[str, object] = {"root_ca_certificate": self.ca}
        if self.cert and self.key:
            tls.update(connect_certificate=self.cert, connect_private_key=self.key, enable_mtls=True)
        conf.insert_json5("transport/link/tls", json.dumps(tls))


def free_tcp_port() -> int:
    """A TCP port that was free a moment ago on loopback (the embedded launcher's pick)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_connected(session: zenoh.Session, timeout: float = 5.0) -> bool:
    """Wait until the session has a link to a router or peer.

    A peer's ``open()`` returns before its connect endpoints are reached; a query sent in that window
    finds nobody. Returns False when nothing connected in time (the caller decides if that is an error).
    """
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if list(session.info.routers_zid()) or list(session.info.peers_zid()):
            return True
        time.sleep(0.01)
    return False


def open_session(settings: ZenohSettings | None = None, *, connect_timeout: float = 5.0) -> zenoh.Session:
    """Open a session and wait (briefly) until it is linked to the network it was told to connect to."""
    settings = settings or ZenohSettings.from_env()
    try:
        session = zenoh.open(settings.to_zenoh())
    except zenoh.ZError as exc:  # zenoh says "Unable to connect ... Timeout!" with a Rust source location
        endpoints = ", ".join(settings.connect) or "(none)"
        raise RouterUnreachable(f"no Zenoh router answers at {endpoints}", detail={"zenoh": str(exc)}) from exc
    if settings.connect:
        wait_connected(session, connect_timeout)
    return session
