"""The asyncio service runtime on a Zenoh session: what every objscan service is built on.

A service subclasses ``Service``, declares its queryables, publishers and subscribers in ``setup()``
with plain ``async def`` handlers, and calls ``run_service(MyService)`` from its ``__main__``. The runtime:

- hands every Zenoh callback straight to the event loop (no work, no Zenoh calls on Zenoh's threads)
  and sends replies from the loop;
- decodes requests strictly, within the key's ``Budget`` (bytes and msgpack elements, checked before the
  payload is copied or parsed), large ones off the event loop; any exception in a handler becomes a typed
  ``Error`` reply and the service keeps running;
- bounds the requests in progress (``max_concurrent``): beyond it a request is answered ``overloaded`` at
  once, undecoded; ``priority`` keys (health, every ``stop``) are never refused, so an e-stop always answers
  while hostile payloads arrive (``objscan bench estop``); ``inline`` keys (the arm's ``stop``,
  health) run a plain function the moment the loop reaches their query, ahead of handlers queued before it;
- answers ``objscan/{service}/{instance}/health`` and holds the liveliness token
  ``objscan/@alive/{service}/{instance}`` for as long as it lives;
- runs CPU-heavy work in an executor (``await self.run_cpu(fn, ...)``) so health keeps answering;
- publishes large data with ``CongestionControl.BLOCK`` (DROP silently loses fragmented messages);
- shuts down cleanly on SIGINT/SIGTERM: tasks cancelled, session closed.
"""

from __future__ import annotations

import argparse
import asyncio
import concurrent.futures
import logging
import os
import signal
import time
import traceback
import uuid
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import zenoh

from common import keys
from common.client import DEFAULT_TIMEOUT_S, request
from common.codec import MAX_PAYLOAD_BYTES, Message, decode
from common.errors import ObjscanError, WireError
from common.fatal import write_fatal
from common.log import event, request_id, setup_logging
from common.memory import tune_malloc
from common.messages import Error, Health
from common.open3d_threads import limit_open3d_threads
from common.zenoh_config import ZenohSettings, wait_connected

log = logging.getLogger("objscan.runtime")

Handler = Callable[[Message | None, "QueryContext"], Awaitable[Message]]
InlineHandler = Callable[[Message | None, "QueryContext"], Message]

INLINE_DECODE_BYTES = 64 * 1024
"""Payloads up to this size are decoded on the event loop (tens of microseconds); larger ones in the decode
thread, so the loop keeps answering ``stop`` and health while a big or hostile payload is parsed."""

MAX_CONCURRENT = 32
"""Requests in progress per service beyond which a new (non-priority) one is refused ``overloaded``."""


@dataclass(frozen=True)
class Budget:
    """What one key accepts: at most ``max_bytes`` of payload and ``max_elements`` msgpack container
    elements (array items + map entries over the whole message; a numpy array counts as one ``bin``)."""

    max_bytes: int = MAX_PAYLOAD_BYTES
    max_elements: int = 1 << 16

    def __post_init__(self) -> None:
        for name in ("max_bytes", "max_elements"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"Budget.{name} must be a positive integer, got {value!r}")
        if self.max_bytes > MAX_PAYLOAD_BYTES:
            raise ValueError(f"Budget.max_bytes {self.max_bytes} exceeds the codec's {MAX_PAYLOAD_BYTES}")


DEFAULT_BUDGET = Budget()
"""Keys that take data (frames, clouds): any size the codec allows, few elements."""

COMMAND_BUDGET = Budget(max_bytes=64 * 1024, max_elements=4096)
"""Commands and queries (a pose, joints, a box, a small config map): a hostile megabyte is refused unread."""


@dataclass
class QueryContext:
    """What a handler may want to know about the query besides its message."""

    key: str
    parameters: str
    request_id: str


@dataclass
class ServiceSettings:
    """Identity and network of one service process."""

    robot: str = keys.DEFAULT_ROBOT
    instance: str = ""
    zenoh: ZenohSettings = field(default_factory=ZenohSettings.from_env)
    cpu_workers: int = max(1, min(4, os.cpu_count() or 1))
    options: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.instance:
            self.instance = os.environ.get("OBJSCAN_INSTANCE") or f"{os.getpid()}-{uuid.uuid4().hex[:4]}"


class AsyncSubscription:
    """Samples of a subscription, delivered to an asyncio queue (drop-oldest when full)."""

    def __init__(self, session: zenoh.Session, key: str, loop: asyncio.AbstractEventLoop, maxsize: int,
                 budget: Budget = DEFAULT_BUDGET):
        self._loop = loop
        self.budget = budget
        self.queue: asyncio.Queue[tuple[str, bytes]] = asyncio.Queue(maxsize=maxsize)
        self._sub = session.declare_subscriber(key, self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:  # zenoh thread: copy out and hand off
        item = (str(sample.key_expr), sample.payload.to_bytes())
        self._loop.call_soon_threadsafe(self._push, item)

    def _push(self, item: tuple[str, bytes]) -> None:
        if self.queue.full():
            self.queue.get_nowait()
        self.queue.put_nowait(item)

    async def get(self) -> tuple[str, Message]:
        """Next decoded sample; undecodable samples are logged and skipped."""
        while True:
            key, payload = await self.queue.get()
            try:
                return key, await decode_within(payload, self.budget)
            except WireError as exc:
                event(log, "dropped malformed sample", logging.WARNING, key=key, code=exc.code)

    def undeclare(self) -> None:
        self._sub.undeclare()


async def decode_within(payload: bytes, budget: Budget,
                        executor: concurrent.futures.Executor | None = None) -> Message:
    """Decode ``payload`` within ``budget``: small ones right here, large ones in ``executor`` (a thread),
    so that parsing never holds the event loop for long."""
    if len(payload) > budget.max_bytes:
        raise WireError("payload too large for this key", code="oversize",
                        detail={"bytes": len(payload), "max": budget.max_bytes})
    if len(payload) <= INLINE_DECODE_BYTES:
        return decode(payload, max_bytes=budget.max_bytes, max_elements=budget.max_elements)
    return await asyncio.get_running_loop().run_in_executor(
        executor, lambda: decode(payload, max_bytes=budget.max_bytes, max_elements=budget.max_elements))


class Publisher:
    """A declared publisher that encodes messages; BLOCK congestion control so large data is not lost."""

    def __init__(self, session: zenoh.Session, key: str, *, block: bool = True):
        cc = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        self.key = key
        self._pub = session.declare_publisher(key, congestion_control=cc,
                                              encoding=zenoh.Encoding("application/msgpack"))

    def put(self, msg: Message) -> None:
        self._pub.put(msg.encode())

    def undeclare(self) -> None:
        self._pub.undeclare()


class Service:
    """Base class of an objscan service. Override ``setup`` (and optionally ``teardown``, ``health_info``)."""

    name = "service"

    def __init__(self, settings: ServiceSettings | None = None):
        self.settings = settings or ServiceSettings()
        self.robot = self.settings.robot
        self.instance = self.settings.instance
        self.session: zenoh.Session | None = None
        self.loop: asyncio.AbstractEventLoop | None = None
        self._declared: list[Any] = []
        self._tasks: set[asyncio.Task[Any]] = set()
        self._busy = 0
        self._bounded = 0  # requests in progress on non-priority keys (bounded by max_concurrent)
        self.max_concurrent = MAX_CONCURRENT
        self.refused_overloaded = 0
        self._started = time.monotonic()
        self._stop = asyncio.Event()
        self._executor = concurrent.futures.ThreadPoolExecutor(max_workers=self.settings.cpu_workers,
                                                               thread_name_prefix=f"{self.name}-cpu")
        # one thread: decoding is GIL-bound, more threads would only take more turns from the loop
        self._decode_executor = concurrent.futures.ThreadPoolExecutor(max_workers=1,
                                                                      thread_name_prefix=f"{self.name}-decode")

    # -------------------------------------------------------------------------------- for subclasses
    async def setup(self) -> None:
        """Declare queryables, publishers and subscribers here."""

    async def teardown(self) -> None:
        """Release hardware and background tasks here; the session is closed afterwards."""

    def health_info(self) -> dict[str, Any]:
        """Extra figures for the health reply (backend, queue depth, ...)."""
        return {}

    def zenoh_config(self) -> zenoh.Config:
        """The Zenoh configuration the session opens with; a service that needs more (timestamps) adds it."""
        return self.settings.zenoh.to_zenoh()

    def queryable(self, key: str, handler: Handler | InlineHandler, *, complete: bool = True,
                  budget: Budget = DEFAULT_BUDGET, priority: bool = False, inline: bool = False) -> None:
        """Serve ``key`` with ``async def handler(request_message_or_None, ctx) -> reply_message``.

        ``budget`` bounds what the key accepts (``COMMAND_BUDGET`` for commands); ``priority`` keys (health,
        ``stop``) are served even when ``max_concurrent`` requests are already in progress. ``inline``: the
        handler is a plain (non-async, quick) function, run and answered as soon as the loop reaches the query
        instead of in a task queued behind the tasks of queries that arrived just before (an e-stop among a
        burst of state queries); its budget must allow inline decoding.
        """
        assert self.session is not None and self.loop is not None
        if inline and budget.max_bytes > INLINE_DECODE_BYTES:
            raise ValueError(f"an inline key's budget must be <= {INLINE_DECODE_BYTES} bytes")
        loop = self.loop

        def on_query(query: zenoh.Query) -> None:  # zenoh thread: hand off only
            if inline:
                loop.call_soon_threadsafe(self._serve_inline, query, handler, budget)
            else:
                loop.call_soon_threadsafe(self._admit, query, handler, budget, priority)

        self._declared.append(self.session.declare_queryable(key, on_query, complete=complete))

    def publisher(self, key: str, *, block: bool = True) -> Publisher:
        assert self.session is not None
        pub = Publisher(self.session, key, block=block)
        self._declared.append(pub)
        return pub

    def subscribe(self, key: str, *, maxsize: int = 16, budget: Budget = DEFAULT_BUDGET) -> AsyncSubscription:
        assert self.session is not None and self.loop is not None
        sub = AsyncSubscription(self.session, key, self.loop, maxsize, budget)
        self._declared.append(sub)
        return sub

    def spawn(self, coro: Awaitable[Any]) -> asyncio.Task[Any]:
        """Run a background coroutine owned by the service (cancelled at shutdown, errors logged)."""
        return self._spawn(coro)

    async def run_cpu(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """Run CPU-heavy ``fn`` in the executor so the loop (and health) stays responsive."""
        assert self.loop is not None
        ctx_id = request_id.get()

        def call() -> Any:
            token = request_id.set(ctx_id)
            try:
                return fn(*args, **kwargs)
            finally:
                request_id.reset(token)

        return await self.loop.run_in_executor(self._executor, call)

    async def request(self, key: str, msg: Message | None = None, *, timeout: float = DEFAULT_TIMEOUT_S) -> Message:
        """Ask another service; raises RemoteError / ServiceUnavailable / RequestTimeout."""
        assert self.session is not None
        rid = request_id.get()
        return await request(self.session, key, msg, timeout=timeout, request_id=None if rid == "-" else rid)

    def stop(self) -> None:
        self._stop.set()

    # -------------------------------------------------------------------------------- machinery
    def _spawn(self, coro: Awaitable[Any]) -> asyncio.Task[Any]:
        task = asyncio.ensure_future(coro)
        self._tasks.add(task)
        task.add_done_callback(self._task_done)
        return task

    def _task_done(self, task: asyncio.Task[Any]) -> None:
        self._tasks.discard(task)
        if not task.cancelled() and task.exception() is not None:
            exc = task.exception()
            event(log, "background task failed", logging.ERROR, error=repr(exc))

    def _admit(self, query: zenoh.Query, handler: Handler, budget: Budget, priority: bool) -> None:
        """On the loop: start serving ``query``, or refuse it at once when too many are in progress."""
        if not priority and self._bounded >= self.max_concurrent:
            self.refused_overloaded += 1
            reply = Error(code="overloaded", message=f"{self.name} has {self._bounded} requests in progress",
                          detail={"max_concurrent": self.max_concurrent}, service=self.name)
            try:
                query.reply(query.key_expr, reply.encode(), encoding=zenoh.Encoding("application/msgpack"))
            except Exception as exc:
                event(log, "could not reply", logging.ERROR, key=str(query.key_expr), error=repr(exc))
            finally:
                query.drop()
            return
        self._spawn(self._serve(query, handler, budget, priority))

    def _serve_inline(self, query: zenoh.Query, handler: InlineHandler, budget: Budget) -> None:
        """On the loop, now: decode (small), run the plain handler, reply; like ``_serve`` without a task."""
        rid = query.attachment.to_bytes().decode(errors="replace")[:64] if query.attachment else uuid.uuid4().hex[:12]
        token = request_id.set(rid)
        key = str(query.key_expr)
        try:
            try:
                payload = query.payload
                if payload is not None and len(payload) > budget.max_bytes:
                    raise WireError("payload too large for this key", code="oversize",
                                    detail={"bytes": len(payload), "max": budget.max_bytes})
                msg = None if payload is None else decode(payload.to_bytes(), max_bytes=budget.max_bytes,
                                                          max_elements=budget.max_elements)
                reply = handler(msg, QueryContext(key=key, parameters=str(query.parameters), request_id=rid))
            except Exception as exc:  # typed or a bug: an Error reply, the service keeps running
                reply = self._error_reply(key, exc)
            query.reply(query.key_expr, reply.encode(), encoding=zenoh.Encoding("application/msgpack"))
        except Exception as exc:
            event(log, "could not reply", logging.ERROR, key=key, error=repr(exc))
        finally:
            query.drop()
            request_id.reset(token)

    def _error_reply(self, key: str, exc: BaseException) -> Error:
        """The ``Error`` reply for a failed request: its typed code, or ``internal`` for a bug (logged)."""
        if isinstance(exc, ObjscanError):
            event(log, "request failed", logging.WARNING, key=key, code=exc.code, error=exc.message)
            return Error(code=exc.code, message=exc.message, detail=_jsonable(exc.detail), service=self.name)
        event(log, "handler crashed", logging.ERROR, key=key, error=repr(exc))
        return Error(code="internal", message=f"{type(exc).__name__}: {exc}",
                     detail={"trace": traceback.format_exc(limit=4)[-2000:]}, service=self.name)

    async def _serve(self, query: zenoh.Query, handler: Handler, budget: Budget = DEFAULT_BUDGET,
                     priority: bool = False) -> None:
        rid = query.attachment.to_bytes().decode(errors="replace")[:64] if query.attachment else uuid.uuid4().hex[:12]
        token = request_id.set(rid)
        key = str(query.key_expr)
        started = time.perf_counter()
        self._busy += 1
        if not priority:
            self._bounded += 1
        try:
            try:
                msg = await self._decode_query(query, budget)
                reply = await handler(msg, QueryContext(key=key, parameters=str(query.parameters), request_id=rid))
            except asyncio.CancelledError:
                reply = Error(code="shutdown", message=f"{self.name} is shutting down", service=self.name)
            except Exception as exc:  # typed, or a handler bug: it must not take the service down
                reply = self._error_reply(key, exc)
            query.reply(query.key_expr, reply.encode(), encoding=zenoh.Encoding("application/msgpack"))
            event(log, "served", logging.DEBUG, key=key, ms=(time.perf_counter() - started) * 1e3,
                  reply=type(reply).__name__)
        except Exception as exc:
            event(log, "could not reply", logging.ERROR, key=key, error=repr(exc))
        finally:
            self._busy -= 1
            if not priority:
                self._bounded -= 1
            query.drop()
            request_id.reset(token)

    async def _decode_query(self, query: zenoh.Query, budget: Budget) -> Message | None:
        """The query's message, within ``budget``; the size is checked before the payload is even copied."""
        payload = query.payload
        if payload is None:
            return None
        size = len(payload)
        if size > budget.max_bytes:
            raise WireError("payload too large for this key", code="oversize",
                            detail={"bytes": size, "max": budget.max_bytes})
        return await decode_within(payload.to_bytes(), budget, self._decode_executor)

    def _health(self, _msg: Message | None, _ctx: QueryContext) -> Message:
        # busy: requests in progress (this health query is served inline, outside the count)
        info = {**self.health_info(), **({"refused_overloaded": self.refused_overloaded}
                                         if self.refused_overloaded else {})}
        return Health(service=self.name, instance=self.instance, status="ok", busy=self._busy,
                      uptime_s=time.monotonic() - self._started, info=_jsonable(info))

    async def run(self) -> None:
        """Open the session, serve until stopped, then shut down cleanly."""
        self.loop = asyncio.get_running_loop()
        self.session = zenoh.open(self.zenoh_config())
        if self.settings.zenoh.connect and not await asyncio.to_thread(wait_connected, self.session, 10.0):
            event(log, "no zenoh link yet; serving anyway, peers may join later", logging.WARNING,
                  connect=",".join(self.settings.zenoh.connect))
        try:
            self.queryable(keys.health(self.name, self.instance), self._health, budget=COMMAND_BUDGET, priority=True,
                           inline=True)
            await self.setup()
            self._declared.append(self.session.liveliness().declare_token(keys.alive(self.name, self.instance)))
            event(log, "ready", robot=self.robot)
            await self._stop.wait()
        finally:
            event(log, "stopping")
            for task in list(self._tasks):
                task.cancel()
            if self._tasks:
                await asyncio.wait(list(self._tasks), timeout=5.0)
            try:
                await self.teardown()
            finally:
                for d in reversed(self._declared):
                    try:
                        d.undeclare()
                    except Exception:  # already gone with the session
                        pass
                self._executor.shutdown(wait=False, cancel_futures=True)
                self._decode_executor.shutdown(wait=False, cancel_futures=True)
                self.session.close()
                event(log, "stopped")


def _jsonable(obj: Any) -> Any:
    """Keep a detail map encodable: numpy scalars to Python, unknown objects to strings."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, (str, int, float, bool, np.ndarray, Message)) or obj is None:
        return obj
    return str(obj)


def service_arg_parser(description: str) -> argparse.ArgumentParser:
    """Arguments every service takes; services add their own (backend, ...)."""
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--robot", default=os.environ.get("OBJSCAN_ROBOT", keys.DEFAULT_ROBOT),
                   help="robot cell id used in key expressions (env OBJSCAN_ROBOT)")
    p.add_argument("--instance", default=os.environ.get("OBJSCAN_INSTANCE", ""),
                   help="instance id (default: pid-based, unique)")
    p.add_argument("--mode", choices=["peer", "client"], help="zenoh mode (env OBJSCAN_ZENOH_MODE)")
    p.add_argument("--connect", help="comma-separated zenoh endpoints (env OBJSCAN_ZENOH_CONNECT)")
    p.add_argument("--listen", help="comma-separated zenoh listen endpoints (env OBJSCAN_ZENOH_LISTEN)")
    p.add_argument("--log-level", default=os.environ.get("OBJSCAN_LOG_LEVEL", "INFO"))
    return p


def settings_from_args(args: argparse.Namespace, **options: Any) -> ServiceSettings:
    z = ZenohSettings.from_env().with_overrides(
        mode=args.mode,
        connect=[e for e in args.connect.split(",") if e] if args.connect else None,
        listen=[e for e in args.listen.split(",") if e] if args.listen else None,
    )
    return ServiceSettings(robot=args.robot, instance=args.instance, zenoh=z, options=options)


def run_service(factory: Callable[[], Service]) -> None:
    """Run a service until SIGINT/SIGTERM; exits non-zero if it failed to start.

    The error that ends the process is logged as one structured line and written where its starter reads it
    (``$OBJSCAN_FATAL_FILE``, ``common/fatal.py``), typed: the starter reports the service's own code."""
    tune_malloc()
    service = factory()
    limit_open3d_threads(only_if_imported=True)  # after the service's imports: reproducible registrations
    setup_logging(service.name, service.instance)

    async def main() -> None:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, service.stop)
        await service.run()

    try:
        asyncio.run(main())
    except Exception as exc:
        # the starter reads why (common/fatal.py): "sim could not start: unknown object ..." in its one line
        payload = write_fatal(service.name, exc)
        code = exc.code if isinstance(exc, ObjscanError) else "internal"
        event(log, "fatal", logging.ERROR, code=code, message=str(getattr(exc, "message", exc))[:300],
              written=payload or "-")
        raise
