"""Start service processes wired to one Zenoh network, wait until they are live, stop them cleanly.

Used by ``objscan up``/``objscan scan`` (the embedded default: a router on loopback and every service its
own OS process) and by tests, which get the same processes on a free port with multicast off. A process
that ends before it is live raises ``ServiceStartError`` with the error it wrote (``common/fatal.py``).
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import zenoh  # noqa: F401 - type of ServiceGroup.session

from common import keys
from common.client import live_services
from common.errors import ServiceStartError
from common.fatal import FATAL_FILE_ENV, read_fatal, start_error
from common.zenoh_config import ZenohSettings, free_tcp_port, open_session


@dataclass
class ProcessSpec:
    """One process to start: a Python module with arguments, and the service name it registers."""

    module: str
    args: list[str] = field(default_factory=list)
    service: str | None = None  # liveliness service name to wait for; None = do not wait
    env: dict[str, str] = field(default_factory=dict)
    name: str = ""

    def label(self) -> str:
        return self.name or self.service or self.module


class ServiceGroup:
    """A router plus service processes sharing one loopback Zenoh network.

    Use as a context manager; on exit every process gets SIGTERM, then SIGKILL after a grace period.
    """

    def __init__(self, port: int | None = None, *, log_dir: Path | None = None, robot: str = keys.DEFAULT_ROBOT,
                 extra_env: dict[str, str] | None = None, start_router: bool = True):
        self.port = port or free_tcp_port()
        self.endpoint = f"tcp/127.0.0.1:{self.port}"
        self.settings = ZenohSettings(mode="client", connect=[self.endpoint])
        self.robot = robot
        self.log_dir = Path(log_dir) if log_dir else None
        self.extra_env = extra_env or {}
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self._logs: list[object] = []
        self._start_router = start_router
        self._session: zenoh.Session | None = None
        self.cleanups: list[Callable[[], object]] = []  # run by stop_all, after the processes (e.g. a lock)
        self._fatal_dir: Path | None = None  # each process's fatal-error file (common/fatal.py), made on first use

    # ---------------------------------------------------------------------------------------------
    def env(self, extra: dict[str, str] | None = None) -> dict[str, str]:
        env = dict(os.environ)
        env.update(self.settings.to_env())
        env["OBJSCAN_ROBOT"] = self.robot
        env.setdefault("OMP_NUM_THREADS", "1")
        env["PYTHONUNBUFFERED"] = "1"
        env.update(self.extra_env)
        env.update(extra or {})
        return env

    def start(self, spec: ProcessSpec) -> subprocess.Popen[bytes]:
        label = spec.label()
        if label in self.procs and self.procs[label].poll() is None:
            raise RuntimeError(f"{label} is already running")
        out: int | object = subprocess.DEVNULL
        if self.log_dir:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            out = open(self.log_dir / f"{label}.log", "ab")  # noqa: SIM115 - closed in stop_all
            self._logs.append(out)
        fatal = self.fatal_path(label)
        fatal.unlink(missing_ok=True)  # an earlier run's reason is not this one's
        env = self.env({FATAL_FILE_ENV: str(fatal), **spec.env})
        proc = subprocess.Popen([sys.executable, "-m", spec.module, *spec.args], env=env,
                                stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        self.procs[label] = proc
        return proc

    def fatal_path(self, label: str) -> Path:
        """Where process ``label`` writes the error that ended it (``common/fatal.py``)."""
        if self._fatal_dir is None:
            self._fatal_dir = Path(tempfile.mkdtemp(prefix="objscan-fatal-"))
            self.cleanups.append(self._drop_fatal_dir)
        return self._fatal_dir / f"{label}.json"

    def _drop_fatal_dir(self) -> None:
        if self._fatal_dir is not None:
            shutil.rmtree(self._fatal_dir, ignore_errors=True)
            self._fatal_dir = None

    def start_error(self, label: str, *, starting: bool = True) -> ServiceStartError:
        """Why process ``label`` ended (while starting, by default): its own typed error when it wrote one."""
        proc = self.procs[label]
        log = self.log_dir / f"{label}.log" if self.log_dir else None
        return start_error(label, proc.poll(), read_fatal(self.fatal_path(label)), log, starting=starting)

    def start_router(self) -> None:
        self.start(ProcessSpec("common.router", ["--listen", self.endpoint], name="router"))
        self.wait_listening("router", timeout=15)

    def wait_listening(self, label: str, timeout: float) -> None:
        """Wait until process ``label`` accepts TCP connections on the group's port (a router, or a peer
        that listens: a peer does not retry a refused connect, so the caller connects only after this)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.port)) == 0:
                    return
            if self.procs[label].poll() is not None:
                raise self.start_error(label)
            time.sleep(0.05)
        raise TimeoutError(f"{label} did not listen on port {self.port}")

    @property
    def session(self) -> zenoh.Session:
        """A client session on the group's network, for status queries and tests."""
        if self._session is None:
            self._session = open_session(self.settings)
        return self._session

    def wait_alive(self, services: Iterable[str], timeout: float = 60.0) -> None:
        wanted = set(services)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            live = {s for s, _ in live_services(self.session, timeout=0.5)}
            if wanted <= live:
                return
            for label, proc in self.procs.items():
                if proc.poll() is not None and label != "router":
                    raise self.start_error(label)
            time.sleep(0.1)
        raise ServiceStartError(f"services not live after {timeout:.0f} s: {', '.join(sorted(wanted - live))}",
                                code="start_timeout", detail={"services": sorted(wanted - live)})

    def launch(self, specs: Sequence[ProcessSpec], timeout: float = 90.0) -> None:
        if self._start_router and "router" not in self.procs:
            self.start_router()
        for spec in specs:
            self.start(spec)
        self.wait_alive([s.service for s in specs if s.service], timeout=timeout)

    def kill(self, label: str, sig: int = signal.SIGKILL) -> None:
        proc = self.procs[label]
        if proc.poll() is None:
            os.killpg(proc.pid, sig)
            proc.wait(timeout=10)

    def stop(self, label: str, grace: float = 8.0) -> int | None:
        proc = self.procs.get(label)
        if proc is None or proc.poll() is not None:
            return None if proc is None else proc.returncode
        try:
            os.killpg(proc.pid, signal.SIGTERM)
            return proc.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            return proc.wait(timeout=5)
        except ProcessLookupError:
            return proc.wait(timeout=5)

    def stop_all(self) -> None:
        if self._session is not None:
            self._session.close()
            self._session = None
        for label in [lbl for lbl in self.procs if lbl != "router"] + (["router"] if "router" in self.procs else []):
            self.stop(label)
        for fh in self._logs:
            fh.close()  # type: ignore[attr-defined]
        self._logs.clear()
        while self.cleanups:
            self.cleanups.pop()()

    def __enter__(self) -> ServiceGroup:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop_all()
