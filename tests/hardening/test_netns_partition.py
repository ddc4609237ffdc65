"""Services on separate 'machines' (network namespaces joined by veth pairs, tc netem latency and loss)
and a partition: a registration worker cut off mid-job has its job retried on another machine, the e-stop
still reaches the arm, and no job is lost.

Machines: ``box`` (router, sim, arm, registration worker wA), ``worker`` (registration worker wB, link
20 ms ± 5 ms, 1 % loss), ``operator`` (the coordinator of a dynamic registration and the e-stop sender,
link 10 ms, 0.5 % loss). Skipped, with the reason, where namespaces cannot be created; where the kernel has
no ``sch_netem`` (this development container) it runs without the added latency and loss and says so."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from common.zenoh_config import ZenohSettings
from tests.hardening.netns import Machines, can_create, netem_missing

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_a_partitioned_worker_has_its_job_retried_elsewhere_and_estop_gets_through(tmp_path):
    reason = can_create()
    if reason:
        pytest.skip(reason)
    m = Machines(["box", "worker", "operator"])
    procs: list[subprocess.Popen] = []
    logs = []

    def start(machine: str, module: str, args: list[str], connect: str, name: str, **kw) -> subprocess.Popen:  # noqa: ANN003
        env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1",
               **ZenohSettings(mode="client", connect=[connect]).to_env()}
        log = open(tmp_path / f"{name}.log", "wb")  # noqa: SIM115 - closed below
        logs.append(log)
        p = m.popen(machine, [sys.executable, "-m", module, *args], env, cwd=REPO,
                    stderr=log, start_new_session=True, **({"stdout": log} | kw))
        procs.append(p)
        return p

    try:
        m.link("box", "worker", 1)
        m.link("box", "operator", 2)
        no_netem = netem_missing()
        if no_netem:  # the partition still runs; latency and loss need the kernel's sch_netem
            print(f"WITHOUT LATENCY/LOSS: {no_netem}")
        else:
            m.netem("box", "worker", "delay 20ms 5ms loss 1%")
            m.netem("box", "operator", "delay 10ms loss 0.5%")
        local = "tcp/127.0.0.1:7447"
        start("box", "common.router", ["--listen", "tcp/0.0.0.0:7447"], local, "router")
        time.sleep(2.0)
        start("box", "services.sim", [], local, "sim")
        start("box", "services.arm", ["--backend", "sim", "--instance", "arm0"], local, "arm")
        start("box", "services.registration", ["--instance", "wA"], local, "wA")
        start("worker", "services.registration", ["--instance", "wB"], f"tcp/{m.addr[('box', 'worker')]}:7447", "wB")
        go = tmp_path / "partitioned"
        driver = start("operator", "tests.hardening.netns_driver", ["wB", "6", str(go)],
                       f"tcp/{m.addr[('box', 'operator')]}:7447", "driver", stdout=subprocess.PIPE)
        line = driver.stdout.readline().decode().strip()
        assert line == "PARTITION wB", (line, (tmp_path / "driver.log").read_text()[-2000:])
        m.partition("box", "worker")  # the worker's machine is cut off mid-job
        go.touch()
        out = driver.stdout.readline().decode().strip()
        driver.wait(timeout=600)
        assert out, (tmp_path / "driver.log").read_text()[-2000:]
        report = json.loads(out)
    finally:
        for p in reversed(procs):
            try:
                os.killpg(p.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
        for log in logs:
            log.close()
        m.close()
    assert "error" not in report["result"], report
    stats = report["stats"]
    assert stats.get("retried", 0) >= 1, stats  # the cut-off worker's job went back to the queue
    done = sum(stats["by_worker"].values())
    assert stats["by_worker"].get("wA", 0) >= 1 and report["result"]["points"] > 10_000
    stops = report["stops_ms"]
    assert stops and all(s >= 0 for s in stops), stops  # every e-stop answered during the partition
    assert sorted(stops)[int(0.99 * (len(stops) - 1))] < 500.0, stops
    print(json.dumps({"jobs_done": done, "stats": stats, "stops": len(stops),
                      "stop_ms_max": max(stops), "seconds": report["seconds"]}))
