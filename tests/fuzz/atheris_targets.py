"""Coverage-guided fuzz targets (atheris / libFuzzer) for the wire decoders.

Run one target for a bounded time::

    python -m tests.fuzz.atheris_targets decode -max_total_time=30 -rss_limit_mb=2048 -timeout=5 CORPUS_DIR

Targets:
- ``decode``: any bytes into ``common.codec.decode``; only ``WireError`` may come out.
- ``unpack_view``: any bytes into ``common.msgpack_view.unpack_view``; only ``ValueError`` may come out, and
  when it parses, ``msgpack.unpackb`` must agree (a differential check of our hand-written reader).

The seed corpus (``write_seed_corpus``) is one valid encoding of every registered message type plus a few
hostile ones, so libFuzzer starts deep inside field validation instead of at the first byte. An uncaught
exception, a libFuzzer timeout (hang) or the RSS limit (memory) is a finding: atheris writes the input to
``crash-*``/``timeout-*``/``oom-*`` and exits non-zero.
"""

from __future__ import annotations

import sys
from pathlib import Path

import atheris

with atheris.instrument_imports(include=["common.codec", "common.msgpack_view", "common.messages", "common.api"]):
    import common.api  # noqa: F401 - registers message types
    import common.messages  # noqa: F401
    from common.codec import decode
    from common.errors import WireError
    from common.msgpack_view import unpack_view

import msgpack  # noqa: E402 - not instrumented: it is the reference, not the target


def _plain(obj: object) -> object:
    if isinstance(obj, memoryview):
        return obj.tobytes()
    if isinstance(obj, list):
        return [_plain(v) for v in obj]
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    return obj


def fuzz_decode(data: bytes) -> None:
    try:
        decode(data)
    except WireError:
        pass


def fuzz_unpack_view(data: bytes) -> None:
    try:
        obj = unpack_view(data)
    except ValueError:
        return
    ref = msgpack.unpackb(data, raw=False, strict_map_key=False)
    if msgpack.packb(_plain(obj)) != msgpack.packb(ref):  # compare packed: NaN != NaN as objects
        raise AssertionError(f"unpack_view disagrees with msgpack on {data[:64]!r}")


TARGETS = {"decode": fuzz_decode, "unpack_view": fuzz_unpack_view}


def write_seed_corpus(folder: Path) -> int:
    """Valid and hostile encodings of every registered message type; returns how many files."""
    import numpy as np
    from hypothesis import HealthCheck, given, settings

    from tests.fuzz.strategies import MESSAGE_TYPES, hostile_wire, pack, valid_message

    folder.mkdir(parents=True, exist_ok=True)
    seeds: list[bytes] = []
    for cls in MESSAGE_TYPES.values():
        @settings(max_examples=3, database=None, deadline=None, suppress_health_check=list(HealthCheck))
        @given(valid_message(cls), hostile_wire(cls))
        def collect(valid, hostile):  # noqa: ANN001
            seeds.append(valid.encode())
            seeds.append(pack(hostile))

        collect()
    seeds.append(pack({"type": "Request", "v": 1, "params": {"a": np.arange(4.0).tolist()}}))
    for i, s in enumerate(seeds):
        (folder / f"seed-{i:04d}").write_bytes(s)
    return len(seeds)


def main() -> None:
    if len(sys.argv) < 2 or sys.argv[1] not in TARGETS:
        sys.exit(f"usage: python -m tests.fuzz.atheris_targets {{{','.join(TARGETS)}}} [libFuzzer args]")
    target = TARGETS[sys.argv[1]]
    atheris.Setup([sys.argv[0], *sys.argv[2:]], target)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
