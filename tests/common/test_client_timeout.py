"""A request whose service matched but answered too late is a typed timeout (``RequestTimeout``, exit code 4 in
the CLI), not an opaque ``remote_error``: zenoh answers such a query with an error reply of its own."""

from __future__ import annotations

import threading
import time

import pytest

from common.client import request_sync
from common.errors import RequestTimeout
from common.messages import Ok


def test_a_service_that_answers_too_late_is_a_request_timeout(service_group):
    key = "objscan/test/slow"
    release = threading.Event()

    def slow(query) -> None:  # noqa: ANN001 - answers after the requester gave up
        release.wait(5.0)
        query.reply(key, Ok(info={}).encode())

    queryable = service_group.session.declare_queryable(key, slow)
    try:
        start = time.monotonic()
        with pytest.raises(RequestTimeout) as err:
            request_sync(service_group.session, key, timeout=1.0)
        assert time.monotonic() - start < 4.0
        assert err.value.code == "timeout" and err.value.detail["key"] == key
    finally:
        release.set()
        queryable.undeclare()
