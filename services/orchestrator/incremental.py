"""The incremental model: pair registrations run during the acquisition, not all at its end.

As soon as view k's static result is saved, the views of the edge "view k onto view k-1" go to the
registration service (``registration/edge``) as a background task: registration builds the edge's pair job in
the first configuration the dynamic stage runs, fingerprints it, runs it on its workers and answers the
result. The orchestrator sends views and receives results; it never builds or sees a pair job. The arm turns
the object to view k+1 meanwhile, and the state machine never waits on it. The same edge's jobs of every other
configuration the automatic choice may run (``no_region_crop``, ``region``, ``region_crop``) follow as
**speculative** jobs: one at a time, in configuration order, and only while no foreground work is in flight (a
static registration, a first-configuration job), so they use the time the arm spends grasping, turning and
scanning and never delay the acquisition or the first configuration. At the end, the orchestrator's
``registration/dynamic`` request carries the finished results (``reuse_pairs``) and the dynamic stage runs
only what is left: the last neighbour pair and the loop closure of each configuration it runs, the
combination, the fusion. Speculative jobs not started when the last view is in are dropped (the dynamic stage
computes them only if the first configuration is rejected); the one in flight is awaited.

Why the result is the same as computing every pair at the end: a job depends only on its two views, view 0
(the stacking frame), the color palette, which the incremental model fits on the first two views
(``preprocess.palette_views = 2``, sent with the final request too), and, for a region configuration, the
regions of its two views (each segmented on its own, fixed seed) and their GOOD pairing
(``model.early_pair_jobs``). Every result is stored with the fingerprint of the job it answers
(``pair.job_fingerprint``); the dynamic stage reuses a result only for the identical job, so a re-scanned
view, another configuration or a changed setting is recomputed, never mixed in.

Persistence: each result is written atomically to ``pairs/edge_KK_<fingerprint>.json`` in the session folder
as soon as it arrives; a resumed orchestrator sends the fingerprints stored for an edge along with its views
(``known``), and registration does not run those jobs again. A job whose worker dies is re-run by another
worker (``dynamic_face.distributed_map``); a coordinating registration instance that dies is re-sent by the
``Cell``. A job that fails is only logged: the dynamic stage then computes that pair at the end, as without
the incremental model.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections import deque
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

from common.api import EdgeRequest
from common.log import event
from services.registration.api import dynamic_configurations, edge_views_needed
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
        self._names: list[str] | None = None  # the configurations the dynamic stage may run, first one first
        self._speculative: deque[tuple[int, int, list[float]]] = deque()  # (source, generation, turns)
        self._speculating: asyncio.Task[None] | None = None
        self._foreground = 0  # static registrations and first-configuration jobs in flight
        self._closing = False
        self._turn: asyncio.Condition | None = None
        self.sent = 0
        self.sent_by_configuration: dict[str, int] = {}

    @property
    def folder(self) -> Path:
        return self.store.path / PAIRS_DIR

    @property
    def names(self) -> list[str]:
        if self._names is None:
            self._names = dynamic_configurations(self.config)
        return self._names

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
                self._tasks[key] = asyncio.ensure_future(self._edge(source, key[1], list(turns_deg)))

    @contextlib.asynccontextmanager
    async def foreground(self) -> AsyncIterator[None]:
        """Work the acquisition waits on (the machine wraps its static registrations in it): no speculative job
        starts meanwhile, so none takes a registration worker's thread or a core from it."""
        self._foreground += 1
        try:
            yield
        finally:
            self._foreground -= 1
            await self._notify()

    async def finished(self) -> list[dict]:
        """Wait for the first configuration's jobs in flight (a failed one is only logged) and the speculative
        job in flight, drop the speculative jobs not started, and return every stored result record."""
        if not self.enabled:
            return []
        self._closing = True
        await self._notify()
        if self._tasks:
            await asyncio.gather(*self._tasks.values(), return_exceptions=True)
        if self._speculating is not None:
            await asyncio.gather(self._speculating, return_exceptions=True)
        dropped = len(self._speculative)
        self._speculative.clear()
        if dropped:
            self.decide("speculative pair jobs left to the dynamic stage", edges=dropped)
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
        self._closing = True
        for t in self._tasks.values():
            t.cancel()
        if self._speculating is not None:
            self._speculating.cancel()

    # ------------------------------------------------------------------------------------------ one edge
    def _path(self, source: int, fingerprint: str) -> Path:
        return self.folder / f"edge_{source - 1:02d}_{fingerprint[:16]}.json"

    def _request(self, source: int, turns_deg: list[float], configuration: str, background: bool) -> EdgeRequest:
        """What registration needs for one configuration's job of edge ``source``: the views it needs (read from
        the session folder: disk and PLY parsing, so in a thread) and the fingerprints of this edge's results
        the session already stores (never computed twice, a restart included)."""
        views = [self.store.load_view(i) for i in edge_views_needed(self.config, source)]
        known = [rec["fingerprint"] for rec in self._stored(source)]
        return EdgeRequest(source=source, views=views, turns_deg=list(turns_deg), config=self.config,
                           configurations=[configuration], known=known, background=background)

    def _stored(self, source: int) -> list[dict]:
        """The stored results of edge ``source`` (any configuration or generation)."""
        if not self.folder.is_dir():
            return []
        out = []
        for p in sorted(self.folder.glob(f"edge_{source - 1:02d}_*.json")):
            rec = self.store.load_json(f"{PAIRS_DIR}/{p.name}")
            if isinstance(rec, dict) and "fingerprint" in rec:
                out.append(rec)
        return out

    async def _edge(self, source: int, generation: int, turns_deg: list[float]) -> None:
        """The first configuration's job of edge ``source``, in the foreground; then the edge's other
        configurations go to the speculative queue."""
        self._foreground += 1
        try:
            await self._send(source, turns_deg, self.names[0], background=False)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # noqa: BLE001 - left to the end: the model is still built, the cause logged
            self.decide("pair job during the acquisition failed; the dynamic stage will compute it",
                        source=source, error=str(exc)[:200])
        finally:
            self._foreground -= 1
        if len(self.names) > 1 and not self._closing:
            self._speculative.append((source, generation, turns_deg))
            if self._speculating is None or self._speculating.done():
                self._speculating = asyncio.ensure_future(self._speculate())
        await self._notify()

    async def _notify(self) -> None:
        if self._turn is None:
            self._turn = asyncio.Condition()
        async with self._turn:
            self._turn.notify_all()

    async def _quiet(self, want_queue: bool) -> bool:
        """Wait until no foreground work is in flight (and, with ``want_queue``, a speculative edge waits);
        False once the acquisition's end has come."""
        if self._turn is None:
            self._turn = asyncio.Condition()
        async with self._turn:
            await self._turn.wait_for(lambda: self._closing or (
                self._foreground == 0 and (bool(self._speculative) or not want_queue)))
        return not self._closing

    async def _speculate(self) -> None:
        """The speculative queue: edge after edge, configuration after configuration, one job at a time."""
        while self._speculative and await self._quiet(want_queue=True):
            source, generation, turns_deg = self._speculative.popleft()
            if generation != self._generation.get(source):
                continue  # the view was re-scanned since: its new edge is queued anew
            try:
                for name in self.names[1:]:
                    if not await self._quiet(want_queue=False):
                        return
                    await self._send(source, turns_deg, name, background=True)
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # noqa: BLE001 - the dynamic stage computes it if it needs it
                self.decide("speculative pair job failed; the dynamic stage will compute it if needed",
                            source=source, error=str(exc)[:200])

    async def _send(self, source: int, turns_deg: list[float], configuration: str, *, background: bool) -> None:
        """Edge ``source``'s views to registration for one configuration; registration builds its job, runs it
        unless the session stores its result already, and each result that comes back is stored at once.
        ``background``: speculative, run at the workers' lowest CPU priority."""
        request = await asyncio.to_thread(self._request, source, turns_deg, configuration, background)
        reply = await self.cell.register_edge(request)
        for rec, name in zip(reply.records, reply.configurations, strict=True):
            self.sent += 1
            self.sent_by_configuration[name] = self.sent_by_configuration.get(name, 0) + 1
            path = self._path(source, str(rec["fingerprint"]))
            self.store.save_json(f"{PAIRS_DIR}/{path.name}", rec)
            self.decide("pair registered during the acquisition", edge=int(rec["index"]), source=source,
                        configuration=name, fitness=round(float(rec["fitness"]), 3),
                        seconds=round(float(rec["seconds"]), 2))
