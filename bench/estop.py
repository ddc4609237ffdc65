"""``objscan bench estop``: how fast the arm answers ``stop`` while hostile payloads arrive.

The cell (router, sim twin, arm with the sim backend) runs as separate processes on loopback. A separate
*hostile* process (``python -m bench.estop --hostile ENDPOINT``, so its work does not share the measuring
process's GIL) sends, each from its own thread, one request after the other (the next as soon as the last
was answered or timed out):

- ``state_bombs`` (3 threads): 5 MB payloads of tiny msgpack arrays to ``arm/state`` (the attack of issue
  17 #9: each took seconds of pure-Python parsing on the arm's event loop, ``stop`` answered after 25.4 s);
- ``element_bomb`` (1 thread): 60 kB payloads of 30,000 empty arrays to ``arm/move`` (under the commands'
  byte budget, over their element budget);
- ``garbage`` (1 thread): random bytes and truncated messages to ``arm/scene``;
- ``flood`` (1 thread): bursts of 64 concurrent valid ``arm/state`` queries (beyond the bound on requests
  in progress).

Meanwhile the measuring process sends ``arm/stop`` every 20 ms and times each round trip. Figures:
``estop_ms_p50``/``estop_ms_p99``/``estop_ms_max`` under that load (target: p99 <= 50 ms), the same without
load (``idle_estop_ms_*``, measured in the same run first), ``stops_answered`` of ``stops_sent``, the arm
still alive, and ``hostile``: what was sent and how the arm answered it (reply codes counted).

``--arm-backend dynamixel --emulate-bus``: the same figures with the real DYNAMIXEL driver on the emulated
PAPRAS bus, plus ``scenarios`` (``bench/_estop_scenarios.py``): the e-stop idle, while streaming, while the
settle check waits for a blocked joint, with one silent servo and with the gripper closing, each with
``estop_ms_p99``, ``sent`` and ``answered`` (target: p99 <= 50 ms everywhere, gripper travel after the stop
< 2 mm). Without those flags the bench runs on the sim backend, as before.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from common import keys
from common.client import request_sync
from common.codec import decode
from common.errors import InvalidRequest
from common.launcher import ProcessSpec, ServiceGroup
from common.messages import Error, Ok
from services.cell import cell_specs

ROBOT = keys.DEFAULT_ROBOT
TARGET_P99_MS = 50.0


# ----------------------------------------------------------------------------------------------- payloads

def tiny_arrays_bomb(total_bytes: int = 5 * 1024 * 1024) -> bytes:
    """A valid msgpack payload of ``total_bytes``: an array of arrays of empty arrays (one byte each).

    Every element is legal, so only a budget on elements (or bytes) stops a reader from walking all of them.
    """
    per = 1 << 20  # the reader's per-container limit
    chunks = max(1, -(-total_bytes // (per + 5)))  # rounded up: at least total_bytes
    inner = b"\xdd" + per.to_bytes(4, "big") + b"\x90" * per
    return b"\xdc" + chunks.to_bytes(2, "big") + inner * chunks


def element_bomb(n: int = 30_000) -> bytes:
    """A small (n + 5 bytes) payload of ``n`` empty arrays: under a command's byte budget, over its elements."""
    return b"\xdd" + n.to_bytes(4, "big") + b"\x90" * n


def garbage(rng: np.random.Generator) -> bytes:
    """Random bytes or a truncated valid header (a map claiming more entries than it has)."""
    if rng.random() < 0.5:
        return rng.integers(0, 256, int(rng.integers(1, 4096)), dtype=np.uint8).tobytes()
    return b"\xdf\x00\x01\x00\x00" + b"\xa1k" * int(rng.integers(1, 100))


# ----------------------------------------------------------------------------------------------- hostile side

def _reply_code(reply: Any) -> str:
    if reply.ok is None:
        return "zenoh_error"
    try:
        msg = decode(reply.ok.payload.to_bytes())
    except Exception:
        return "undecodable"
    return msg.code if isinstance(msg, Error) else type(msg).__name__


def hostile_main(endpoint: str, robot: str, out: Path, stop_file: Path) -> None:
    """Send the hostile load until ``stop_file`` exists; then write what was sent and answered to ``out``."""
    import zenoh

    from common.zenoh_config import ZenohSettings

    session = zenoh.open(ZenohSettings(mode="client", connect=[endpoint]).to_zenoh())
    counts: dict[str, Counter[str]] = {}
    sent: Counter[str] = Counter()
    lock = threading.Lock()
    state_bomb = tiny_arrays_bomb()
    small_bomb = element_bomb()

    def record(kind: str, code: str) -> None:
        with lock:
            counts.setdefault(kind, Counter())[code] += 1

    def sender(kind: str, key: str, payload_fn: Any) -> None:
        while not stop_file.exists():
            payload = payload_fn()
            with lock:
                sent[kind] += 1
            try:
                replies = list(session.get(key, payload=payload, timeout=5.0))
            except Exception:  # the session closing at the end
                return
            record(kind, _reply_code(replies[0]) if replies else "no_reply")

    def flood() -> None:
        while not stop_file.exists():
            try:
                receivers = [session.get(keys.arm(robot, "state"), timeout=5.0) for _ in range(64)]
                with lock:
                    sent["flood"] += len(receivers)
                for r in receivers:
                    replies = list(r)
                    record("flood", _reply_code(replies[0]) if replies else "no_reply")
            except Exception:  # the session closing at the end
                return
            time.sleep(0.05)

    rng = np.random.default_rng(17)
    threads = [threading.Thread(target=sender, args=("state_bombs", keys.arm(robot, "state"), lambda: state_bomb))
               for _ in range(3)]
    threads.append(threading.Thread(target=sender, args=("element_bomb", keys.arm(robot, "move"),
                                                         lambda: small_bomb)))
    threads.append(threading.Thread(target=sender, args=("garbage", keys.arm(robot, "scene"),
                                                         lambda: garbage(rng))))
    threads.append(threading.Thread(target=flood))
    for t in threads:
        t.daemon = True
        t.start()
    for t in threads:
        t.join(timeout=30.0)
    out.write_text(json.dumps({"sent": dict(sent), "answers": {k: dict(v) for k, v in counts.items()},
                               "payload_bytes": {"state_bombs": len(state_bomb), "element_bomb": len(small_bomb),
                                                 "garbage": "1-4096"}}))
    session.close()


def describe_hostile_load() -> dict[str, Any]:
    return {
        "state_bombs": "3 threads, each one request after the other: 5 MB msgpack of ~5M empty arrays to arm/state",
        "element_bomb": "1 thread: 30,005-byte payload of 30,000 empty arrays to arm/move",
        "garbage": "1 thread: random bytes (1-4096) or truncated maps to arm/scene",
        "flood": "1 thread: bursts of 64 concurrent valid arm/state queries every 50 ms",
        "process": "a separate process (its own GIL), connected to the same router",
    }


class HostileLoad:
    """The hostile process: started, stopped, its counts read back."""

    def __init__(self, group: ServiceGroup, robot: str = ROBOT):
        self.dir = Path(tempfile.mkdtemp(prefix="objscan-hostile-"))
        self.stop_file = self.dir / "stop"
        self.out = self.dir / "counts.json"
        self.proc = subprocess.Popen([sys.executable, "-m", "bench.estop", "--hostile", group.endpoint,
                                      "--robot", robot, "--out", str(self.out), "--stop-file", str(self.stop_file)],
                                     env=group.env())

    def stop(self) -> dict[str, Any]:
        self.stop_file.touch()
        try:
            self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        return json.loads(self.out.read_text()) if self.out.is_file() else {"error": "hostile process wrote nothing"}


# ----------------------------------------------------------------------------------------------- measuring

def time_stops(session: Any, robot: str, n: int, period_s: float = 0.02, timeout_s: float = 30.0) -> list[float]:
    """Round-trip times (ms) of ``n`` ``arm/stop`` requests; a stop not answered counts as ``timeout_s``."""
    out = []
    for _ in range(n):
        t0 = time.perf_counter()
        try:
            reply = request_sync(session, keys.arm(robot, "stop"), timeout=timeout_s)
            ok = isinstance(reply, Ok) and reply.info.get("estopped") is True
        except Exception:
            ok = False
        dt = (time.perf_counter() - t0) * 1e3
        out.append(dt if ok else timeout_s * 1e3)
        time.sleep(period_s)
    return out


def _pct(values: list[float], q: float) -> float:
    return round(float(np.percentile(values, q)), 2)


def run(quick: bool = False, arm_backend: str = "sim", emulate_bus: bool = False) -> dict[str, Any]:
    """The figures above; with ``arm_backend="dynamixel", emulate_bus=True`` the arm runs the DYNAMIXEL
    driver on its emulated PAPRAS bus and ``scenarios`` adds the e-stop in each situation of
    ``bench/_estop_scenarios.py`` (idle, streaming, settling with a blocked joint, a silent servo, the
    gripper closing)."""
    if arm_backend not in ("sim", "dynamixel"):
        raise InvalidRequest(f"bench estop runs on the sim or the dynamixel arm backend, not {arm_backend!r}",
                             code="bad_value", detail={"arm_backend": arm_backend})
    if arm_backend == "dynamixel" and not emulate_bus:
        raise InvalidRequest("bench estop on the dynamixel backend needs --emulate-bus (it injects faults into "
                             "the emulated bus; it never drives a real arm)", code="bad_value",
                             detail={"arm_backend": arm_backend})
    n = 100 if quick else 500
    work = Path(tempfile.mkdtemp(prefix="objscan-bench-estop-"))
    specs = cell_specs(["sim", "arm"])
    fault_file = work / "bus-faults.json"
    if arm_backend == "dynamixel":
        from services.arm.drivers.dynamixel.emulator import FAULT_FILE_ENV, write_faults

        write_faults(fault_file, {})
        specs = [sp if sp.service != "arm" else ProcessSpec(
            sp.module, ["--backend", "dynamixel", "--option", "emulate_bus=true"], service="arm",
            env={FAULT_FILE_ENV: str(fault_file)}) for sp in specs]
    scenarios: dict[str, Any] | None = None
    with ServiceGroup(log_dir=work) as group:
        group.launch(specs, timeout=180)
        s = group.session
        idle = time_stops(s, ROBOT, max(20, n // 5))
        hostile = HostileLoad(group)
        time.sleep(3.0)  # the hostile senders are connected and sending
        loaded = time_stops(s, ROBOT, n)
        load = hostile.stop()
        alive = group.procs["arm"].poll() is None
        try:  # the arm still answers its health query once the load is gone
            health = request_sync(s, keys.health("arm", "*"), timeout=30) if alive else None
        except Exception:
            health = None
        if arm_backend == "dynamixel" and alive:
            from bench._estop_scenarios import run_scenarios
            from services.arm.drivers.dynamixel.robot_config import load_robot_config

            scenarios = run_scenarios(s, ROBOT, fault_file, np.asarray(load_robot_config().home), quick)
    answered = sum(1 for v in loaded if v < 30_000)
    extra: dict[str, Any] = {}
    if scenarios is not None:
        extra = {"arm_backend": arm_backend, "emulate_bus": emulate_bus, "scenarios": scenarios,
                 "scenarios_meet_target": all(b["estop_ms_p99"] <= TARGET_P99_MS and b["answered"] == b["sent"]
                                              for b in scenarios.values())}
    return {
        "estop_ms_p50": _pct(loaded, 50), "estop_ms_p99": _pct(loaded, 99), "estop_ms_max": _pct(loaded, 100),
        "stops_sent": len(loaded), "stops_answered": answered,
        "idle_estop_ms_p50": _pct(idle, 50), "idle_estop_ms_p99": _pct(idle, 99),
        "target_p99_ms": TARGET_P99_MS, "meets_target": _pct(loaded, 99) <= TARGET_P99_MS,
        "arm_alive_after": alive and health is not None,
        "hostile": {"load": describe_hostile_load(), **load},
        "load_average": list(os.getloadavg()),
        **extra,
    }


def main() -> None:
    p = argparse.ArgumentParser(description="hostile side of objscan bench estop")
    p.add_argument("--hostile", required=True, help="router endpoint")
    p.add_argument("--robot", default=ROBOT)
    p.add_argument("--out", required=True)
    p.add_argument("--stop-file", required=True)
    a = p.parse_args()
    hostile_main(a.hostile, a.robot, Path(a.out), Path(a.stop_file))


if __name__ == "__main__":
    main()
