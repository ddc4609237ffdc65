"""Sending requests to objscan services, from asyncio code or from plain scripts.

A request is a Zenoh ``get`` carrying one encoded message; the reply is decoded, and an ``Error`` reply
becomes a ``RemoteError`` with the remote code, so callers handle failures as exceptions with stable
codes. No reply at all becomes ``ServiceUnavailable`` (nobody serves that key) or ``RequestTimeout``
(somebody does but did not answer in time): every request has a timeout.
"""

from __future__ import annotations

import asyncio
import threading
import time
import uuid
from typing import Any

import zenoh

from common import keys
from common.codec import Message, decode
from common.errors import RemoteError, RequestTimeout, ServiceUnavailable, WireError
from common.messages import Error

DEFAULT_TIMEOUT_S = 30.0
ZENOH_QUERY_TIMEOUT = b"Timeout"  # the error reply zenoh gives a query whose matched queryable answered too late


def _new_request_id() -> str:
    return uuid.uuid4().hex[:12]


def _interpret(key: str, replies: list[tuple[bool, bytes]], elapsed: float, timeout: float) -> Message:
    if not replies:
        if elapsed >= timeout * 0.95:
            raise RequestTimeout(f"no reply from {key} within {timeout:.1f} s", detail={"key": key})
        raise ServiceUnavailable(f"no service answers {key}", detail={"key": key})
    ok, payload = replies[0]
    if not ok and payload == ZENOH_QUERY_TIMEOUT:  # a service matched the key but answered too late
        raise RequestTimeout(f"{key} matched a service that did not answer within {timeout:.1f} s",
                             detail={"key": key})
    if not ok:
        try:
            msg = decode(payload)
        except WireError:
            raise RemoteError(f"{key} failed: {payload[:200].decode(errors='replace')}",
                              detail={"key": key}) from None
    else:
        msg = decode(payload)
    if isinstance(msg, Error):
        raise RemoteError(msg.message or msg.code, code=msg.code, detail={**msg.detail, "key": key})
    return msg


def _collector(replies: list[tuple[bool, bytes]]):  # noqa: ANN202 - a zenoh reply callback
    """A reply callback that copies each reply's payload out (ok or error) into ``replies``."""

    def on_reply(reply: zenoh.Reply) -> None:
        if reply.ok is not None:
            replies.append((True, reply.ok.payload.to_bytes()))
        else:
            replies.append((False, reply.err.payload.to_bytes()))

    return on_reply


def _get_args(msg: Message | None, request_id: str | None) -> dict[str, Any]:
    args: dict[str, Any] = {"attachment": (request_id or _new_request_id()).encode()}
    if msg is not None:
        args["payload"] = msg.encode()
        args["encoding"] = zenoh.Encoding("application/msgpack")
    return args


async def request(session: zenoh.Session, key: str, msg: Message | None = None, *,
                  timeout: float = DEFAULT_TIMEOUT_S, request_id: str | None = None,
                  target: zenoh.QueryTarget | None = None) -> Message:
    """Send one request and await its decoded reply without blocking the event loop."""
    loop = asyncio.get_running_loop()
    fut: asyncio.Future[None] = loop.create_future()
    replies: list[tuple[bool, bytes]] = []

    on_reply = _collector(replies)

    def on_done() -> None:
        loop.call_soon_threadsafe(lambda: fut.done() or fut.set_result(None))

    start = time.monotonic()
    kwargs = _get_args(msg, request_id)
    if target is not None:
        kwargs["target"] = target
    session.get(key, zenoh.handlers.Callback(on_reply, on_done), timeout=timeout, **kwargs)
    await fut
    return _interpret(key, replies, time.monotonic() - start, timeout)


def request_sync(session: zenoh.Session, key: str, msg: Message | None = None, *,
                 timeout: float = DEFAULT_TIMEOUT_S, request_id: str | None = None) -> Message:
    """Blocking variant for scripts, the CLI and tests."""
    done = threading.Event()
    replies: list[tuple[bool, bytes]] = []

    on_reply = _collector(replies)

    start = time.monotonic()
    session.get(key, zenoh.handlers.Callback(on_reply, done.set), timeout=timeout, **_get_args(msg, request_id))
    done.wait(timeout + 5.0)
    return _interpret(key, replies, time.monotonic() - start, timeout)


def live_services(session: zenoh.Session, timeout: float = 1.0) -> list[tuple[str, str]]:
    """(service, instance) of every service holding a liveliness token right now."""
    out = []
    for reply in session.liveliness().get(keys.ALL_ALIVE, timeout=timeout):
        if reply.ok is not None:
            parsed = keys.parse_alive(str(reply.ok.key_expr))
            if parsed:
                out.append(parsed)
    return sorted(set(out))
