"""The orchestrator's side of the live view: every exchange of a run, published on ``.../orchestrator/tap``.

A scan started with ``live: true`` (``objscan scan --rerun/--rerun-save/--foxglove``) has its Cell's
requester wrapped like the recorder's: after each successful request the request and its reply go out as
one ``Request`` message, ``params = {key, request, reply, t_sent, t_received}`` (the same messages the
recording stores). Publishing never blocks the acquisition: congestion control DROP, so a slow or absent
viewer loses samples instead of stalling the arm.
"""

from __future__ import annotations

import time
from collections.abc import Awaitable, Callable
from typing import Any

from common import keys
from common.codec import Message
from common.messages import Request
from common.runtime import Publisher

Requester = Callable[..., Awaitable[Message]]


def tap_key(robot: str) -> str:
    return keys.orchestrator(robot, "tap")


def tap_message(key: str, request: Message | None, reply: Message, t_sent: float, t_received: float) -> Request:
    return Request(params={"key": key, "request": request, "reply": reply, "t_sent": float(t_sent),
                           "t_received": float(t_received)})


def tapped(send: Requester, zenoh_session: Any, robot: str) -> Requester:
    """A requester that behaves like ``send`` and publishes every successful exchange on the tap key."""
    pub = Publisher(zenoh_session, tap_key(robot), block=False)

    async def send_tapped(key: str, msg: Message | None = None, **kwargs: Any) -> Message:
        t0 = time.time()
        reply = await send(key, msg, **kwargs)
        pub.put(tap_message(key, msg, reply, t0, time.time()))
        return reply

    return send_tapped
