"""A cell on loopback behind the shipped TLS + access-control router, each service with its own identity.

Shared by the security tests: makes a lab CA and certificates in a temporary folder (``objscan certs``),
starts ``tests.security.tls_router`` (the shipped policy) and the requested services, each given only its
own certificate through ``OBJSCAN_ZENOH_TLS_*``.
"""

from __future__ import annotations

from pathlib import Path

import zenoh

from common.launcher import ProcessSpec, ServiceGroup
from common.zenoh_config import TlsSettings, ZenohSettings, free_tcp_port
from services.cell import cell_specs
from services.cli.cmd_certs import generate_lab_certs


def identity_tls(certs: Path, identity: str | None) -> TlsSettings:
    """TLS settings of one identity (``None``: trusts the CA but shows no certificate)."""
    if identity is None:
        return TlsSettings(ca=str(certs / "ca.pem"))
    return TlsSettings(ca=str(certs / "ca.pem"), cert=str(certs / f"{identity}.pem"),
                       key=str(certs / f"{identity}.key"))


def identity_env(certs: Path, identity: str) -> dict[str, str]:
    return identity_tls(certs, identity).to_env()


class TlsCell:
    """Router + services with per-identity certificates; ``open(identity)`` gives a client session."""

    def __init__(self, root: Path, router_config: Path | None = None):
        self.root = Path(root)
        self.router_config = router_config
        self.certs = self.root / "certs"
        generate_lab_certs(self.certs)
        self.port = free_tcp_port()
        self.endpoint = f"tls/localhost:{self.port}"
        self.group = ServiceGroup(self.port, log_dir=self.root / "logs", start_router=False)
        # the group's own session (liveliness polling in wait_alive) is the operator's
        self.group.settings = ZenohSettings(mode="client", connect=[self.endpoint],
                                           tls=identity_tls(self.certs, "operator"))
        self._sessions: list[zenoh.Session] = []

    def start_router(self, timeout: float = 20.0) -> None:
        args = ["--certs", str(self.certs), "--listen", f"tls/127.0.0.1:{self.port}"]
        if self.router_config is not None:
            args += ["--config", str(self.router_config)]
        self.group.start(ProcessSpec("tests.security.tls_router", args, name="router"))
        self.group.wait_listening("router", timeout)

    def launch(self, services: list[str], timeout: float = 120.0) -> None:
        specs = cell_specs(services, extra_args={"orchestrator": ["--sessions", str(self.root)]})
        for spec in specs:
            spec.env.update(identity_env(self.certs, spec.service or spec.module))
        self.group.launch(specs, timeout=timeout)

    def settings(self, identity: str | None, *, certs: Path | None = None, endpoint: str | None = None,
                 connect_timeout_ms: int = 3000) -> ZenohSettings:
        tls = identity_tls(certs or self.certs, identity)
        return ZenohSettings(mode="client", connect=[endpoint or self.endpoint], tls=tls,
                             connect_timeout_ms=connect_timeout_ms)

    def open(self, identity: str | None, **kwargs: object) -> zenoh.Session:
        """A client session as ``identity``; raises ``zenoh.ZError`` when the router refuses the link."""
        session = zenoh.open(self.settings(identity, **kwargs).to_zenoh())  # type: ignore[arg-type]
        self._sessions.append(session)
        return session

    def close(self) -> None:
        for s in self._sessions:
            try:
                s.close()
            except Exception:
                pass
        self.group.stop_all()
