"""A simulated cell for fault injection: the real services as processes, an acquisition driven through the
orchestrator's ``run`` key (as ``objscan scan`` does), and a fault injector that kills a service while it
is serving a request and starts it again.

"Mid-operation" is made exact: the injector waits until the orchestrator is in the given state (and view)
*and* the victim's health says a request is inside one of its handlers, then SIGKILLs the victim's process
group (no clean shutdown, no goodbye to the router), waits ``down_s`` and starts the same service again.
"""

from __future__ import annotations

import hashlib
import json
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from common import keys
from common.client import live_services, request_sync
from common.codec import decode
from common.errors import ObjscanError
from common.launcher import ProcessSpec, ServiceGroup
from common.messages import Health, Ok, Request
from services.cell import cell_specs

ROBOT = keys.DEFAULT_ROBOT
WORKER_MODULE = "tests.faults.registration_worker"  # services.registration + a bug workaround (see there)
SCAN_CONFIG = {"object": "milk", "views": 3, "profile": "robot-turned", "seed": 0, "width": 640, "height": 480}
"""``objscan scan``'s defaults with 3 views: the profile with real turn errors and slips."""


def cell_processes(sessions: Path, registration_workers: int = 2) -> list[ProcessSpec]:
    """Every service (sim backends) plus extra registration workers labelled ``registration-2``, ..."""
    specs = cell_specs()
    for spec in specs:
        if spec.service == "orchestrator":
            spec.args += ["--sessions", str(sessions)]
        if spec.service == "registration":
            spec.module = WORKER_MODULE
    for k in range(2, registration_workers + 1):
        specs.append(ProcessSpec(WORKER_MODULE, [], service="registration", name=f"registration-{k}"))
    return specs


@dataclass
class Fault:
    """Kill ``label`` when the orchestrator is in ``state`` (and ``view``, if given) and the victim is busy."""

    label: str
    state: str
    view: int | None = None
    down_s: float = 2.0
    busy_key_service: str | None = None  # service name whose health to watch (default: the label's)
    fired_at: dict[str, Any] = field(default_factory=dict)

    @property
    def service(self) -> str:
        return self.busy_key_service or self.label.split("-")[0].rstrip("*")


class FaultInjector(threading.Thread):
    """Fires each fault once, in order, as soon as its victim is seen busy in (or after) the fault's state.

    ``last`` is the orchestrator's latest status, set from the status stream's callback, so the injector
    always sees the current state; the victim's health is polled every few milliseconds, which catches
    even short handlers (grasp planning takes ~0.3 s). A fault whose state passes without the victim
    being seen busy stays armed for the next time the state comes round (``view`` is a lower bound).
    """

    def __init__(self, group: ServiceGroup, specs: dict[str, ProcessSpec], faults: list[Fault]):
        super().__init__(daemon=True)
        self.group = group
        self.specs = specs
        self.faults = list(faults)
        self.last: dict[str, Any] = {}
        self.done = threading.Event()
        self.errors: list[str] = []
        self.fired: list[Fault] = []
        self._instances: dict[str, str] = {}

    def _instance_of(self, label: str, timeout: float = 60.0) -> str | None:
        """The liveliness instance of process ``label`` (instance ids start with the service's pid)."""
        pid = self.group.procs[label].pid
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for _service, inst in live_services(self.group.session, timeout=0.5):
                if inst.startswith(f"{pid}-"):
                    return inst
            time.sleep(0.1)
        return None

    def _busy(self, service: str, instance: str) -> int:
        try:
            h = request_sync(self.group.session, keys.health(service, instance), timeout=1.0)
        except ObjscanError:
            return 0
        return h.busy if isinstance(h, Health) else 0  # Health.busy excludes the health query itself

    def _victims(self, fault: Fault) -> list[str]:
        if fault.label == "registration*":  # whichever registration worker is busy
            return [lbl for lbl in self.group.procs if lbl.startswith("registration")]
        return [fault.label]

    def _armed(self, fault: Fault) -> bool:
        st = self.last
        return st.get("state") == fault.state and (fault.view is None or int(st.get("view", -1)) >= fault.view)

    def _kill_and_restart(self, fault: Fault, label: str, instance: str) -> None:
        fault.fired_at = {"label": label, "instance": instance, "state": self.last.get("state"),
                          "view": self.last.get("view"), "t": time.time()}
        self.group.kill(label)
        time.sleep(fault.down_s)
        self.group.start(self.specs[label])
        self.fired.append(fault)
        inst = self._instance_of(label)
        if inst is None:
            self.errors.append(f"{label} did not come back after the fault")
        else:
            self._instances[label] = inst

    def run(self) -> None:
        for label in self.group.procs:
            if label != "router":
                inst = self._instance_of(label, timeout=10.0)
                if inst:
                    self._instances[label] = inst
        pending = list(self.faults)
        while not self.done.is_set() and pending:
            if self.last.get("status") in ("done", "failed", "stopped"):
                break
            fault = pending[0]
            if not self._armed(fault):
                time.sleep(0.02)
                continue
            for label in self._victims(fault):
                inst = self._instances.get(label)
                if inst and self._busy(fault.service, inst) > 0:
                    self._kill_and_restart(fault, label, inst)
                    pending.pop(0)
                    break
            else:
                time.sleep(0.005)
        self.errors.extend(f"{f.label}: not fired (run ended in {self.last.get('state')})" for f in pending)


def run_acquisition(group: ServiceGroup, out: Path, specs: dict[str, ProcessSpec], faults: list[Fault] | None = None,
                    *, config: dict[str, Any] | None = None, timeout_s: float = 1800) -> tuple[dict[str, Any],
                                                                                                 FaultInjector]:
    """Start one acquisition through ``orchestrator/run`` and follow it to the end, injecting ``faults``."""
    injector = FaultInjector(group, specs, faults or [])
    final: dict[str, Any] = {}
    finished = threading.Event()

    def on_status(sample) -> None:  # noqa: ANN001 - zenoh thread
        try:
            msg = decode(sample.payload.to_bytes())
        except ObjscanError:
            return
        if isinstance(msg, Ok):
            injector.last = msg.info
            if msg.info.get("status") in ("done", "failed", "stopped"):
                final.update(msg.info)
                finished.set()

    sub = group.session.declare_subscriber(keys.orchestrator(ROBOT, "status"), on_status)
    injector.start()
    try:
        reply = request_sync(group.session, keys.orchestrator(ROBOT, "run"),
                             Request(params={"out": str(out), "config": {**SCAN_CONFIG, **(config or {})}}),
                             timeout=30)
        assert isinstance(reply, Ok)
        if not finished.wait(timeout_s):
            final.update(request_sync(group.session, keys.orchestrator(ROBOT, "status"), timeout=10).info)
            final.setdefault("status", "timeout")
    finally:
        injector.done.set()
        injector.join(timeout=150)
        sub.undeclare()
    return final, injector


@dataclass
class SessionSummary:
    views: int
    frames_per_view: list[int]
    frame_hashes: list[str]  # frames of the final views
    all_frame_hashes: list[str]  # every frame on disk: locate, final views, set-aside attempts
    captures: int  # the orchestrator's own count of captures it saved
    status: str

    @property
    def frames(self) -> int:
        return sum(self.frames_per_view)


def summarize(session: Path) -> SessionSummary:
    """Views registered, complete frames per final view, and a hash of every frame's pixels."""
    journal = json.loads((session / "journal.json").read_text())
    views = sorted(d for d in session.glob("view_[0-9][0-9]") if (d / "view.json").is_file())
    per_view, hashes = [], []
    for v in views:
        scans = sorted(s for s in v.glob("scan_*") if (s / "meta.json").is_file())
        per_view.append(len(scans))
        for s in scans:
            hashes.append(_frame_hash(s))
    every = [_frame_hash(m.parent) for m in sorted(session.rglob("scan_*/meta.json"))]
    return SessionSummary(views=len(views), frames_per_view=per_view, frame_hashes=hashes, all_frame_hashes=every,
                          captures=int(journal["counters"]["captures"]), status=journal["status"])


def _frame_hash(scan: Path) -> str:
    return hashlib.sha256((scan / "color.png").read_bytes() + (scan / "depth.png").read_bytes()).hexdigest()


def start_cell(root: Path, registration_workers: int = 2) -> tuple[ServiceGroup, dict[str, ProcessSpec]]:
    # the twin's state file (services/sim/state_file.py) in the test's folder, not the user's state dir
    group = ServiceGroup(log_dir=root / "logs", extra_env={"OBJSCAN_STATE_DIR": str(root / "state")})
    specs = cell_processes(root, registration_workers)  # sessions go under root (the orchestrator's root)
    try:
        group.launch(specs, timeout=300)
    except BaseException:
        group.stop_all()
        raise
    return group, {s.label(): s for s in specs}
