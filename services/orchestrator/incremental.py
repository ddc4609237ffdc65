"""The incremental model: pair registrations run during the acquisition, not all at its end.

As soon as view k's static result is saved, the pair job "view k onto view k-1" is built and sent to the
registration workers (``registration/pair``) as a background task: the arm turns the object to view k+1
meanwhile, and the state machine never waits on it. At the end, the orchestrator's ``registration/dynamic``
request carries the finished results (``reuse_pairs``) and the dynamic stage runs only what is left (the
last neighbour pair, the loop closure, the combination, the fusion).

Why the result is the same as computing every pair at the end: a job depends only on its two views, view
0 (the stacking frame) and the color palette, which the incremental model fits on the first two views
(``preprocess.palette_views = 2``, sent with the final request too). Every result is stored with the
fingerprint of the job it answers (``pair.job_fingerprint``); the dynamic stage reuses a result only for
the identical job, so a re-scanned view, another configuration or a changed setting is recomputed, never
mixed in.

Persistence: each result is written atomically to ``pairs/edge_KK_<fingerprint>.json`` in the session
folder as soon as it arrives; a resumed orchestrator finds it there and does not send the job again. A
job whose worker dies is re-run by another worker (``dynamic_face.distributed_map``); a coordinating
registration instance that dies is re-sent by the ``Cell``. A job that fails is only logged: the dynamic
stage then computes that pair at the end, as without the incremental model.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

from common.log import event
from services.session_store import SessionStore

log = logging.getLogger("objscan.orchestrator")

PAIRS_DIR = "pairs"
PALETTE_VIEWS = 2  # the palette of the incremental model: fitted on views 0 and 1, known once view 1 is in


def dynamic_request_config(config: dict, incremental: bool) -> dict:
    """The dynamic stage's config for this acquisition: with the incremental model, the palette comes from the
    first views (unless the session set ``preprocess.palette_views`` itself), during the run and at the end."""
    if not incremental:
        return dict(config)
    pre = dict(config.get("preprocess") or {})
    pre.setdefault("palette_views", PALETTE_VIEWS)
    return {**config, "preprocess": pre}


class IncrementalModel:
    """Sends each neighbour pair job as soon as its two views are registered; keeps the results on disk."""

    def __init__(self, store: SessionStore, dynamic_config: dict, cell: Any, *, enabled: bool = True,
                 decide: Callable[..., None] | None = None):
        self.store = store
        self.enabled = enabled
        self.config = dynamic_request_config(dynamic_config, enabled)
        self.cell = cell
        self.decide = decide or (lambda what, **kw: event(log, what, **kw))
        self._tasks: dict[tuple[int, int], asyncio.Task[None]] = {}  # (source view, generation) -> task
        self._generation: dict[int, int] = {}
        self.sent = 0

    @property
    def folder(self) -> Path:
        return self.store.path / PAIRS_DIR

    # ------------------------------------------------------------------------------------------ scheduling
    def view_ready(self, k: int, turns_deg: list[float]) -> None:
        """View ``k`` was just registered (perhaps again, after a re-scan): start its pair job, and those of
        any earlier edge not started yet (a resume), in the background. Returns at once."""
        if self.enabled and (k, self._generation.get(k, 0)) in self._tasks:  # view k anew: a new job
            self._generation[k] += 1
        self.catch_up(k, turns_deg)

    def catch_up(self, k: int, turns_deg: list[float]) -> None:
        """Start the pair job of every edge up to view ``k`` whose views are registered and that was not
        started by this orchestrator yet; a job already stored in the session folder is not sent again."""
        if not self.enabled:
            return
        for source in range(1, k + 1):
            if source >= len(turns_deg) or not (self.store.has_view(source) and self.store.has_view(source - 1)):
                continue
            key = (source, self._generation.setdefault(source, 0))
            if key not in self._tasks:
                self._tasks[key] = asyncio.ensure_future(self._edge(source, list(turns_deg)))

    async def finished(self) -> list[dict]:
        """Wait for the jobs in flight (a failed one is only logged) and return every stored result record."""
        if not self.enabled:
            return []
        if self._tasks:
            await asyncio.gather(*self._tasks.values(), return_exceptions=True)
        return await asyncio.to_thread(self.records)

    def records(self) -> list[dict]:
        """Every pair result stored in the session folder (any job; the dynamic stage reuses exact matches)."""
        out = []
        for p in sorted(self.folder.glob("edge_*.json")) if self.folder.is_dir() else []:
            rec = self.store.load_json(f"{PAIRS_DIR}/{p.name}")
            if isinstance(rec, dict) and "fingerprint" in rec:
                out.append(rec)
        return out

    def close(self) -> None:
        """Cancel jobs in flight (the run stopped or failed); stored results stay for a resume."""
        for t in self._tasks.values():
            t.cancel()

    # ------------------------------------------------------------------------------------------ one edge
    def _path(self, source: int, fingerprint: str) -> Path:
        return self.folder / f"edge_{source - 1:02d}_{fingerprint[:16]}.json"

    def _job(self, source: int, turns_deg: list[float]):  # noqa: ANN202 - (PairJob, fingerprint) | None
        """Build the job exactly as the dynamic stage will (same conversion, same config): CPU, in a thread."""
        from services.registration.dynamic.model import early_pair_job
        from services.registration.dynamic.pair import job_fingerprint
        from services.registration.dynamic_face import dynamic_config, dynamic_view

        cfg = dynamic_config(self.config)
        needed = sorted({0, *range(cfg.preprocess.palette_views), source - 1, source})
        views = {i: dynamic_view(self.store.load_view(i), turns_deg[i], i) for i in needed}
        job = early_pair_job(views, source, cfg)
        return None if job is None else (job, job_fingerprint(job))

    async def _edge(self, source: int, turns_deg: list[float]) -> None:
        from services.registration.pair_wire import pair_job_message, pair_record, pair_result_from_message

        try:
            built = await asyncio.to_thread(self._job, source, turns_deg)
            if built is None:
                return
            job, fingerprint = built
            path = self._path(source, fingerprint)
            if path.is_file():  # finished before a restart: never sent twice
                return
            self.sent += 1
            reply = await self.cell.register_pair(pair_job_message(job))
            result = pair_result_from_message(reply)
            self.store.save_json(f"{PAIRS_DIR}/{path.name}", pair_record(fingerprint, result))
            self.decide("pair registered during the acquisition", edge=job.index, source=source,
                        fitness=round(result.fitness, 3), seconds=round(result.seconds, 2))
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # noqa: BLE001 - left to the end: the model is still built, the cause logged
            self.decide("pair job during the acquisition failed; the dynamic stage will compute it",
                        source=source, error=str(exc)[:200])
