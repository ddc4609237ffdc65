"""Dynamic registration spread over every live registration worker.

``build_model`` runs in the coordinating worker's executor; its ``map_pairs`` hands each pair job to a
worker found by liveliness (this one included) over ``registration/worker/{instance}/pair``. One thread
per worker pulls jobs from a shared queue, so faster workers take more. A worker whose liveliness token
vanishes, or that stops answering, loses its job back to the queue for another worker; if no worker is
left the coordinator finishes the remaining jobs itself. Results come back in job order.
"""

from __future__ import annotations

import asyncio
import logging
import queue
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

import zenoh

from common import keys
from common.api import DynamicRequest, EdgeReply, EdgeRequest, ModelResult
from common.codec import Message, decode
from common.errors import InvalidRequest, RemoteError, WireError
from common.log import event
from services.registration.api import (
    PairJob,
    PairResult,
    PairResultMessage,
    build_model,
    dynamic_config,
    edge_reply,
    edge_work,
    model_cloud,
    pair_job_from_message,
    pair_job_message,
    pair_result_from_message,
    pair_result_message,
    register_pair,
    reuse_records,
    views_from_results,
)


class ServiceContext(Protocol):
    """What the distributed paths use of the registration service: its Zenoh session (to find live workers)
    and its executor. A protocol, so this module and ``service.py`` (which calls it) do not import each other."""

    session: zenoh.Session
    instance: str
    pair_slots: int

    async def run_cpu(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any: ...

log = logging.getLogger("objscan.registration")
PAIR_TIMEOUT_S = 600.0


class WorkerLost(Exception):
    """The worker running a job died or went silent; the job goes back to the queue."""


class LiveWorkers:
    """The set of live registration instances, kept current by a liveliness subscriber."""

    def __init__(self, session: zenoh.Session):
        self._lock = threading.Lock()
        self.alive: set[str] = set()
        self._sub = session.liveliness().declare_subscriber(f"{keys.ALIVE_PREFIX}/registration/*", self._on,
                                                            history=True)

    def _on(self, sample: zenoh.Sample) -> None:
        parsed = keys.parse_alive(str(sample.key_expr))
        if not parsed:
            return
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self.alive.add(parsed[1])
            else:
                self.alive.discard(parsed[1])

    def snapshot(self) -> set[str]:
        with self._lock:
            return set(self.alive)

    def close(self) -> None:
        self._sub.undeclare()


def _run_on_worker(session: zenoh.Session, workers: LiveWorkers, instance: str, job: PairJob,
                   background: bool = False) -> PairResult:
    """Send one job to one worker and wait, giving up as soon as the worker vanishes."""
    done = threading.Event()
    replies: list[tuple[bool, bytes]] = []

    def on_reply(reply: zenoh.Reply) -> None:
        replies.append((reply.ok is not None, (reply.ok or reply.err).payload.to_bytes()))

    session.get(keys.registration_worker_pair(instance), zenoh.handlers.Callback(on_reply, done.set),
                payload=pair_job_message(job, background).encode(), timeout=PAIR_TIMEOUT_S)
    while not done.wait(0.25):
        if instance not in workers.snapshot():
            raise WorkerLost(instance)
    if not replies:
        raise WorkerLost(instance)
    ok, payload = replies[0]
    try:
        msg = decode(payload)
    except WireError as exc:
        raise RemoteError(f"worker {instance} sent an undecodable reply", code="bad_reply") from exc
    if isinstance(msg, PairResultMessage):
        return pair_result_from_message(msg)
    code = getattr(msg, "code", "bad_reply")
    if code in ("shutdown", "unavailable"):
        raise WorkerLost(instance)
    raise RemoteError(getattr(msg, "message", "pair job failed"), code=code)


def distributed_map(session: zenoh.Session, stats: dict, own_instance: str | None = None,  # noqa: ANN201 - MapPairs
                    slots: int = 1, background: bool = False):
    """A ``map_pairs`` for ``build_model`` that spreads jobs over the live workers, ``slots`` jobs at a time
    to each (a worker runs that many in its processes, ``pair_pool.py``).

    ``own_instance`` (the coordinating instance) is offered jobs last: it is also answering the request, so a
    lone job goes to another worker when there is one. ``background``: the jobs run at the workers' lowest
    CPU priority (speculative work)."""

    def map_pairs(jobs: list[PairJob]) -> list[PairResult]:
        workers = LiveWorkers(session)
        try:
            time.sleep(0.2)  # liveliness history arrives asynchronously
            # results by position in ``jobs``: one call may hold several configurations' jobs of the same edge
            pending: queue.Queue[tuple[int, PairJob]] = queue.Queue()
            for item in enumerate(jobs):
                pending.put(item)
            results: dict[int, PairResult] = {}
            errors: list[BaseException] = []
            lock = threading.Lock()

            def worker_loop(instance: str) -> None:
                while not errors:
                    try:
                        pos, job = pending.get_nowait()
                    except queue.Empty:
                        return
                    try:
                        res = _run_on_worker(session, workers, instance, job, background)
                    except WorkerLost:
                        pending.put((pos, job))
                        with lock:
                            stats["retried"] = stats.get("retried", 0) + 1
                        event(log, "worker lost; job re-queued", logging.WARNING, worker=instance, job=job.index)
                        return
                    except BaseException as exc:  # a real failure of the job: stop everything
                        errors.append(exc)
                        return
                    with lock:
                        results[pos] = res
                        stats.setdefault("by_worker", {}).setdefault(instance, 0)
                        stats["by_worker"][instance] += 1

            while len(results) < len(jobs) and not errors:
                live = sorted(workers.snapshot(), key=lambda w: (w == own_instance, w))
                if not live:  # nobody left: do the rest here
                    while not pending.empty():
                        pos, job = pending.get_nowait()
                        results[pos] = register_pair(job)
                    break
                threads = [threading.Thread(target=worker_loop, args=(w,), daemon=True)
                           for w in live for _ in range(max(1, slots))]
                for t in threads:
                    t.start()
                for t in threads:
                    t.join()
            if errors:
                raise errors[0]
            return [results[pos] for pos in range(len(jobs))]
        finally:
            workers.close()

    return map_pairs


async def register_pair_distributed(service: ServiceContext, msg: Message | None) -> PairResultMessage:
    """One pair job (``registration/pair``), run by a live worker; a worker that dies has it re-run by another.

    The incremental model sends pair jobs here during the acquisition; the answer is the job's result.
    """
    job = pair_job_from_message(msg)
    stats: dict = {}
    run = distributed_map(service.session, stats, service.instance, background=bool(getattr(msg, "background", False)))
    (result,) = await asyncio.to_thread(run, [job])
    return pair_result_message(result)


async def register_edge_distributed(service: ServiceContext, msg: Message | None) -> EdgeReply:
    """One edge of the incremental model (``registration/edge``): its jobs are built and fingerprinted here
    from the views the orchestrator sent (CPU, in the executor), those not stored yet run on the live
    workers (a worker that dies has its job re-run by another), and the results come back with their
    fingerprints. The orchestrator never builds or sees a pair job."""
    if not isinstance(msg, EdgeRequest):
        raise InvalidRequest("expected an EdgeRequest", detail={"got": type(msg).__name__})
    jobs = await service.run_cpu(edge_work, msg)
    if not jobs:
        return edge_reply([], [])
    stats: dict = {}
    run = distributed_map(service.session, stats, service.instance, background=msg.background)
    results = await asyncio.to_thread(run, [e.job for e in jobs])
    return edge_reply(jobs, results)


async def build_model_distributed(service: ServiceContext, msg: Message | None) -> ModelResult:
    if not isinstance(msg, DynamicRequest):
        raise InvalidRequest("expected a DynamicRequest", detail={"got": type(msg).__name__})
    views = views_from_results(msg.views, msg.turns_deg)
    config = dynamic_config(msg.config)
    reuse = reuse_records(msg.config.get("reuse_pairs", []))
    stats: dict = {}
    map_pairs = distributed_map(service.session, stats, service.instance, service.pair_slots)
    result = await service.run_cpu(build_model, views, config, map_pairs, reuse=reuse)
    figures = result.to_json()
    figures["workers"] = stats
    return ModelResult(cloud=model_cloud(result), figures=figures)


__all__ = ["build_model_distributed", "distributed_map", "register_edge_distributed", "register_pair_distributed"]
