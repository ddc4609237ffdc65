"""Network namespaces for tests: 'machines' on one host, joined by veth pairs, with tc netem.

Every address lives inside the namespaces the helper creates (10.217.x.0/24); nothing is routed to the host's
own interfaces, and ``close()`` deletes the namespaces (and with them the veths and qdiscs).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import uuid


class NetnsUnavailable(RuntimeError):
    """Namespaces cannot be created here (not root, no CAP_NET_ADMIN, no iproute2)."""


def _ip(*args: str) -> None:
    out = subprocess.run(["ip", *args], capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {out.stderr.strip()}")


class Machines:
    """Named namespaces ('machines') and the links between them."""

    def __init__(self, names: list[str]):
        if shutil.which("ip") is None or shutil.which("tc") is None:
            raise NetnsUnavailable("iproute2 (ip, tc) is not installed")
        tag = uuid.uuid4().hex[:6]
        self.ns = {n: f"objscan-{tag}-{n}" for n in names}
        self.links: dict[tuple[str, str], tuple[str, str]] = {}
        self.addr: dict[tuple[str, str], str] = {}
        created = []
        try:
            for ns in self.ns.values():
                _ip("netns", "add", ns)
                created.append(ns)
                _ip("-n", ns, "link", "set", "lo", "up")
        except RuntimeError as exc:
            for ns in created:
                subprocess.run(["ip", "netns", "del", ns], capture_output=True)
            raise NetnsUnavailable(str(exc)) from None

    def link(self, a: str, b: str, subnet: int) -> None:
        """A veth pair a<->b with 10.217.<subnet>.1 on a and .2 on b."""
        ia, ib = f"v{subnet}{a}", f"v{subnet}{b}"
        _ip("link", "add", ia, "netns", self.ns[a], "type", "veth", "peer", "name", ib, "netns", self.ns[b])
        for ns, dev, host in ((self.ns[a], ia, 1), (self.ns[b], ib, 2)):
            _ip("-n", ns, "addr", "add", f"10.217.{subnet}.{host}/24", "dev", dev)
            _ip("-n", ns, "link", "set", dev, "up")
        self.links[(a, b)] = (ia, ib)
        self.addr[(a, b)] = f"10.217.{subnet}.1"
        self.addr[(b, a)] = f"10.217.{subnet}.2"

    def netem(self, a: str, b: str, spec: str, *, change: bool = False) -> None:
        """``tc netem`` on both ends of the a-b link (e.g. 'delay 20ms 5ms loss 1%', 'loss 100%')."""
        ia, ib = self.links[(a, b)]
        for ns, dev in ((self.ns[a], ia), (self.ns[b], ib)):
            out = subprocess.run(["ip", "netns", "exec", ns, "tc", "qdisc", "change" if change else "add", "dev", dev,
                                  "root", "netem", *spec.split()], capture_output=True, text=True)
            if out.returncode != 0:
                raise RuntimeError(f"tc netem {spec} on {dev}: {out.stderr.strip()}")

    def partition(self, a: str, b: str) -> None:
        """Cut the a-b link (both ends down: packets vanish, no reset is sent; like a pulled cable)."""
        ia, ib = self.links[(a, b)]
        _ip("-n", self.ns[a], "link", "set", ia, "down")
        _ip("-n", self.ns[b], "link", "set", ib, "down")

    def popen(self, machine: str, argv: list[str], env: dict[str, str], **kw) -> subprocess.Popen:  # noqa: ANN003
        return subprocess.Popen(["ip", "netns", "exec", self.ns[machine], *argv], env=env, **kw)

    def close(self) -> None:
        for ns in self.ns.values():
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)


def netem_missing() -> str | None:
    """None when ``tc netem`` works here, else the reason (containers often lack the sch_netem module)."""
    m = Machines(["probe"])
    try:
        out = subprocess.run(["ip", "netns", "exec", m.ns["probe"], "tc", "qdisc", "add", "dev", "lo", "root",
                              "netem", "delay", "1ms"], capture_output=True, text=True)
        return None if out.returncode == 0 else f"tc netem unavailable: {out.stderr.strip()}"
    finally:
        m.close()


def can_create() -> str | None:
    """None when namespaces can be created here, else the reason."""
    if os.geteuid() != 0:
        return "network namespaces need root (CAP_NET_ADMIN)"
    try:
        Machines(["probe"]).close()
    except NetnsUnavailable as exc:
        return str(exc)
    return None
