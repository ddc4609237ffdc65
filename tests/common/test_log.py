"""The log keeps a traceback's last line at info level and the whole traceback at debug level."""

from __future__ import annotations

import io
import logging

import pytest

from common.log import setup_logging


@pytest.fixture
def captured():
    root = logging.getLogger()
    saved = root.handlers[:], root.level
    setup_logging("test", "t0", "INFO")
    stream = io.StringIO()
    root.handlers[0].setStream(stream)
    yield stream
    root.handlers[:], _ = saved
    root.setLevel(saved[1])


def _fail(log: logging.Logger) -> None:
    try:
        {}["missing"]
    except KeyError:
        log.warning("lookup failed", exc_info=True)


def test_info_level_keeps_one_line_with_the_exception(captured):
    _fail(logging.getLogger("objscan.t"))
    lines = captured.getvalue().splitlines()
    assert len(lines) == 1 and "lookup failed" in lines[0] and 'exc="KeyError: \'missing\'"' in lines[0]


def test_debug_level_adds_the_full_traceback(captured):
    logging.getLogger().setLevel(logging.DEBUG)
    _fail(logging.getLogger("objscan.t"))
    lines = captured.getvalue().splitlines()
    assert 'exc="KeyError' in lines[0]
    assert lines[1].strip() == "Traceback (most recent call last):"
    assert any("in _fail" in ln for ln in lines) and all(ln.startswith("    ") for ln in lines[1:])
