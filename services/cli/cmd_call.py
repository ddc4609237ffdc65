"""``objscan call KEY [JSON]``: send one request and print the decoded reply (for debugging)."""

from __future__ import annotations

import json

import numpy as np

from common.client import request_sync
from common.codec import Message, registered_types
from common.errors import ObjscanError
from common.messages import Request
from common.zenoh_config import open_session
from services.cli.cells import add_network_args, network_settings
from services.cli.outcome import BadUsage


def register(sub) -> None:  # noqa: ANN001
    p = sub.add_parser("call", help="send one request to a key and print the reply",
                       description="JSON with a 'type' key builds that message (arrays as nested lists); "
                                   "other JSON is sent as Request(params=JSON).")
    p.add_argument("key", help="zenoh key, e.g. objscan/robot0/arm/state")
    p.add_argument("json", nargs="?", help="request body as JSON")
    p.add_argument("--timeout", type=float, default=30.0,
                   help="seconds to wait for the reply (default: %(default)s)")
    p.add_argument("--json", dest="json_output", action="store_true",
                   help="a failure is also one JSON object on stdout (the reply is always printed as JSON)")
    add_network_args(p)
    p.set_defaults(func=run)


def message_from_json(text: str | None) -> Message | None:
    if not text:
        return None
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise BadUsage(f"the request body is not JSON: {exc}") from None
    if isinstance(data, dict) and "type" in data:
        cls = registered_types().get(data.pop("type"))
        if cls is None:
            raise BadUsage(f"unknown message type; known: {', '.join(sorted(registered_types()))}")
        import dataclasses
        import typing

        hints = typing.get_type_hints(cls)
        kwargs = {}
        for f in dataclasses.fields(cls):
            if f.name in data:
                v = data[f.name]
                kwargs[f.name] = np.asarray(v, dtype=f.metadata["array"].dtype) if "array" in f.metadata else v
        del hints
        return cls(**kwargs)
    return Request(params=data if isinstance(data, dict) else {"value": data})


def summarize(value):  # noqa: ANN001, ANN201 - printable view of any decoded value
    if isinstance(value, np.ndarray):
        if value.size <= 16:
            return value.tolist()
        return f"<array {value.dtype} {list(value.shape)}>"
    if isinstance(value, Message):
        import dataclasses

        return {"type": type(value).__name__, **{f.name: summarize(getattr(value, f.name))
                                                 for f in dataclasses.fields(value)}}
    if isinstance(value, dict):
        return {k: summarize(v) for k, v in value.items()}
    if isinstance(value, list):
        return [summarize(v) for v in value]
    return value


def run(args) -> int:  # noqa: ANN001
    msg = message_from_json(args.json)
    session = open_session(network_settings(args.connect))
    try:
        reply = request_sync(session, args.key, msg, timeout=args.timeout)
    except ObjscanError as exc:  # the service's own code and message, on the CLI's one line
        exc.detail = summarize(exc.detail)
        raise
    finally:
        session.close()
    print(json.dumps(summarize(reply), indent=2, default=str))
    return 0
