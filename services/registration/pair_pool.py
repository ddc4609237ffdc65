"""Pair jobs in worker processes of a registration instance, so one instance runs several at once.

Why processes: a pair registration holds the GIL most of its time (Open3D's pybind calls, scipy, numpy on
small arrays): two pair jobs in two threads of one process took as long as one after the other (measured,
milk ``realistic`` region_crop pairs: 4.5 s serial, 4.5 s in two threads). In processes they use both cores,
which is what the dynamic stage's shared rounds (``model.run_configurations``: the other configurations'
last edges and loop closures when the first is rejected) need to be faster than one by one; and an
incremental-model pair job no longer takes turns at the GIL with a static registration in the service's
threads. Background jobs (``PairJobMessage.background``: the incremental model's speculative jobs) go to a
second pool of one process at niceness 19: on the twin the simulator's physics and rendering are CPU work
too, and a speculative job must not slow the acquisition it runs beside.

The processes are spawned (not forked: Open3D's thread pools do not survive a fork) and run one Open3D
thread each (``limit_open3d_threads``, the service's own ``OMP_NUM_THREADS``), so a job gives the same result
bit for bit as in the service process. A process that dies (out of memory) breaks the pool: it is rebuilt,
and the job is answered ``unavailable`` so the caller's ``distributed_map`` runs it again.
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from common.errors import ObjscanError
from common.log import event

log = logging.getLogger("objscan.registration")


def _init_worker(threads: str, nice: int) -> None:
    os.environ["OMP_NUM_THREADS"] = threads
    if nice:
        os.nice(nice)
    from common.open3d_threads import limit_open3d_threads
    from services.registration.dynamic import pair  # noqa: F401 - imported once, before the first job

    limit_open3d_threads()


def _warm() -> None:
    """Nothing: submitting it makes the pool start its processes (and import) before the first job."""


class PairPool:
    """``processes`` spawned workers running ``register_pair``; ``run`` awaits one job's result. ``nice``: the
    workers' CPU niceness (19 for background work: it yields every core to the acquisition's processes)."""

    def __init__(self, processes: int, nice: int = 0):
        self.processes = max(1, int(processes))
        self.nice = int(nice)
        self._pool = self._start()

    def _start(self) -> ProcessPoolExecutor:
        from common.open3d_threads import open3d_thread_count

        pool = ProcessPoolExecutor(max_workers=self.processes, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_init_worker, initargs=(str(open3d_thread_count()), self.nice))
        for _ in range(self.processes):
            pool.submit(_warm)
        return pool

    async def run(self, job: Any) -> Any:
        from services.registration.dynamic.pair import register_pair

        try:
            return await asyncio.wrap_future(self._pool.submit(register_pair, job))
        except BrokenProcessPool:
            event(log, "pair worker process died; pool restarted", logging.WARNING, job=getattr(job, "index", None))
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = self._start()
            raise ObjscanError("a pair worker process died", code="unavailable") from None

    async def niceness(self) -> int:
        """The workers' niceness as they see it (tests)."""
        return await asyncio.wrap_future(self._pool.submit(os.nice, 0))

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
