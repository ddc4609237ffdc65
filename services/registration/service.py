"""The registration service's Zenoh face.

- ``objscan/registration/static``: the scans of one view → the isolated object (``ViewResult``).
- ``objscan/registration/dynamic``: registered views → the model; its pair jobs are spread over every
  live registration worker (found by liveliness), a job whose worker dies is retried on another.
- ``objscan/registration/edge``: the views of one edge of the incremental model (during an acquisition)
  → its pair results: the jobs are built, fingerprinted and run on this side, spread over the live workers.
- ``objscan/registration/pair``: one pair job, run by a live worker; retried on another when that worker
  dies.
- ``objscan/registration/worker/{instance}/pair``: one pair job, answered by this worker.

Every instance is a worker; any one of them can coordinate a dynamic request. The algorithms live in
``static/`` and ``dynamic/`` as plain functions; this module only decodes, schedules and encodes.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable

from common import keys
from common.api import StaticRequest, ViewResult
from common.codec import Message
from common.errors import InvalidRequest
from common.runtime import QueryContext, Service, run_service, service_arg_parser, settings_from_args
from services.registration.api import pair_job_from_message, pair_result_message, register_scans, view_result
from services.registration.dynamic_face import (
    build_model_distributed,
    register_edge_distributed,
    register_pair_distributed,
)

# registers PairJobMessage/PairResultMessage with the codec: a pair job is decoded before its handler runs
from services.registration.pair_pool import PairPool


class RegistrationService(Service):
    name = "registration"

    async def setup(self) -> None:
        self.jobs_done = {"static": 0, "pair": 0, "edge": 0, "dynamic": 0}
        self.coordinating = 0
        self.pairs_running = 0
        # pair jobs run in processes (pair_pool.py): several at once per instance, none sharing the static
        # stage's GIL; distributed_map sends each live worker this many at a time
        self.pair_pool = PairPool(self.settings.cpu_workers)
        self.background_pool = PairPool(1, nice=19)
        self.pair_slots = self.pair_pool.processes
        self.queryable(keys.REGISTRATION_STATIC, self.static)
        self.queryable(keys.registration_worker_pair(self.instance), self.pair)
        self.queryable(keys.REGISTRATION_DYNAMIC, self.dynamic)
        self.queryable(keys.REGISTRATION_PAIR, self.pair_any)
        self.queryable(keys.REGISTRATION_EDGE, self.edge)

    async def static(self, msg: Message | None, ctx: QueryContext) -> ViewResult:
        if not isinstance(msg, StaticRequest):
            raise InvalidRequest("expected a StaticRequest", detail={"got": type(msg).__name__})
        result = await self.run_cpu(register_scans, msg.frames, msg.profile, msg.pose_accuracy)
        self.jobs_done["static"] += 1
        return view_result(msg.view, result)

    async def pair(self, msg: Message | None, ctx: QueryContext) -> Message:
        job = pair_job_from_message(msg)
        self.pairs_running += 1  # in health: which worker is computing a pair right now
        try:
            pool = self.background_pool if getattr(msg, "background", False) else self.pair_pool
            result = await pool.run(job)
        finally:
            self.pairs_running -= 1
        self.jobs_done["pair"] += 1
        return pair_result_message(result)

    async def _coordinate(self, run: Callable[[RegistrationService, Message | None], Awaitable[Message]],
                          msg: Message | None, done: str | None = None) -> Message:
        """Answer ``msg`` by ``run`` (work spread over the live workers); health counts it as coordinating
        while it runs and, once answered, under ``jobs_done[done]``."""
        self.coordinating += 1
        try:
            reply = await run(self, msg)
        finally:
            self.coordinating -= 1
        if done is not None:
            self.jobs_done[done] += 1
        return reply

    async def pair_any(self, msg: Message | None, ctx: QueryContext) -> Message:
        return await self._coordinate(register_pair_distributed, msg)

    async def edge(self, msg: Message | None, ctx: QueryContext) -> Message:
        return await self._coordinate(register_edge_distributed, msg, "edge")

    async def dynamic(self, msg: Message | None, ctx: QueryContext) -> Message:
        return await self._coordinate(build_model_distributed, msg, "dynamic")

    async def teardown(self) -> None:
        self.pair_pool.close()
        self.background_pool.close()

    def health_info(self) -> dict[str, object]:
        return {**self.jobs_done, "coordinating": self.coordinating, "pairs_running": self.pairs_running}


def main() -> None:
    args = service_arg_parser("objscan registration service (static, pair worker, dynamic)").parse_args()
    run_service(lambda: RegistrationService(settings_from_args(args)))
