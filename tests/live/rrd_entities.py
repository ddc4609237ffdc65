"""Reading an ``.rrd`` back with the Rerun SDK (``rerun.chunk.RrdReader``): entity → components, row counts."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path


def rrd_entities(path: str | Path) -> dict[str, dict[str, int]]:
    """entity path → {component column → rows}, over every chunk of the file's recording."""
    from rerun.chunk import RrdReader

    out: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for chunk in RrdReader(path).store().stream():
        for name in chunk.to_record_batch().schema.names:
            if ":" in name:  # component columns are Archetype:field; skip row ids and timelines
                out[chunk.entity_path][name] += chunk.num_rows
    return {k: dict(v) for k, v in out.items()}
