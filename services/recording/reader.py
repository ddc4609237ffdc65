"""Reading recordings back: complete files, files cut short by a crash, and sessions in several parts.

``read_recording`` streams every record (``mcap.stream_reader.StreamReader``), so it needs neither the
summary nor the footer a killed writer never wrote: it returns what is on disk up to the last complete
record and says ``truncated``. ``recover`` rewrites such a file into a complete one (what ``mcap
recover`` does), so any MCAP tool, Foxglove included, opens it.
"""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.records import Channel, DataEnd, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from common.codec import Message as WireMessage
from common.codec import decode
from services.recording.errors import RecordingError
from services.recording.recorder import RAW_ENCODING, recording_parts


@dataclass
class Exchange:
    """One recorded request and its reply (exact payload bytes), in the order the orchestrator sent them."""

    key: str
    sequence: int
    request: bytes
    reply: bytes
    t_sent: float
    t_received: float
    part: int = 0
    t_received_ns: int = 0  # the record's exact log time (float seconds lose ~0.2 us at today's epoch)

    def request_message(self) -> WireMessage | None:
        return decode(self.request) if self.request else None

    def reply_message(self) -> WireMessage:
        return decode(self.reply)


@dataclass
class Recording:
    """Everything read from one or more recording files of a session."""

    paths: list[Path]
    metadata: dict[str, dict[str, Any]] = field(default_factory=dict)
    exchanges: list[Exchange] = field(default_factory=list)
    samples: dict[str, list[tuple[float, bytes]]] = field(default_factory=dict)
    sample_ns: dict[str, list[int]] = field(default_factory=dict)  # exact log times, parallel to ``samples``
    counts: dict[str, int] = field(default_factory=dict)  # topic -> messages read
    channels: dict[str, dict[str, Any]] = field(default_factory=dict)  # topic -> encoding, schema, metadata
    truncated: list[Path] = field(default_factory=list)  # files that ended without a footer

    def exchanges_on(self, key: str) -> list[Exchange]:
        return [e for e in self.exchanges if e.key == key]

    def run_config(self) -> dict[str, Any]:
        """The acquisition config the recorded run was started with (``session`` metadata)."""
        cfg = self.metadata.get("session", {}).get("config")
        if not isinstance(cfg, dict):
            raise RecordingError(f"{self.paths[0]} has no session config in its metadata")
        return cfg


def _parse_metadata(values: dict[str, str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in values.items():
        try:
            out[k] = json.loads(v)
        except (json.JSONDecodeError, TypeError):
            out[k] = v
    return out


def iter_records(path: Path) -> Iterator[Any]:
    """Every record of ``path`` (chunks opened), stopping quietly at a record cut short by a crash.

    Yields the records; the last item is ``("truncated", bool)`` so callers learn whether it ended cleanly.
    """
    ended = False
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f, skip_magic=False).records:
                if isinstance(record, (DataEnd, Footer)):
                    ended = True
                yield record
        except (McapError, EOFError, struct.error, zlib.error, ValueError, RuntimeError):
            pass  # a torn tail: everything before it was yielded
    yield ("truncated", not ended)


def _files(source: str | Path) -> list[Path]:
    p = Path(source)
    if p.is_dir():
        files = recording_parts(p)
        if not files:
            raise RecordingError(f"{p} holds no session.mcap", detail={"path": str(p)})
        return files
    if not p.is_file():
        raise RecordingError(f"no recording at {p}", detail={"path": str(p)})
    return [p]


def read_recording(source: str | Path) -> Recording:
    """Read a recording file, or every part of a session folder's recording, in order."""
    files = _files(source)
    rec = Recording(paths=files)
    for part, path in enumerate(files):
        channels: dict[int, Channel] = {}
        schemas: dict[int, Schema] = {}
        pending: dict[tuple[str, int], Message] = {}
        try:
            records = list(iter_records(path))
        except OSError as exc:
            raise RecordingError(f"cannot read {path}: {exc}", detail={"path": str(path)}) from None
        if not records or len(records) == 1:
            raise RecordingError(f"{path} is not an MCAP recording (no record could be read)",
                                 detail={"path": str(path)})
        for record in records:
            if isinstance(record, tuple):
                if record[1]:
                    rec.truncated.append(path)
            elif isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
                schema = schemas.get(record.schema_id)
                rec.channels.setdefault(record.topic, {"encoding": record.message_encoding,
                                                       "schema": schema.name if schema else None,
                                                       "metadata": dict(record.metadata)})
            elif isinstance(record, Metadata):
                if part == 0 or record.name not in rec.metadata:
                    rec.metadata[record.name] = _parse_metadata(record.metadata)
                else:
                    rec.metadata[f"{record.name}.part{part}"] = _parse_metadata(record.metadata)
            elif isinstance(record, Message):
                ch = channels.get(record.channel_id)
                if ch is None:
                    continue
                rec.counts[ch.topic] = rec.counts.get(ch.topic, 0) + 1
                if ch.message_encoding != RAW_ENCODING:
                    continue
                kind, key = ch.metadata.get("kind"), ch.metadata.get("zenoh_key", ch.topic)
                if kind == "request":
                    pending[(key, record.sequence)] = record
                elif kind == "reply":
                    req = pending.pop((key, record.sequence), None)
                    rec.exchanges.append(Exchange(
                        key=key, sequence=record.sequence, request=req.data if req is not None else b"",
                        reply=record.data, t_sent=record.publish_time / 1e9, t_received=record.log_time / 1e9,
                        part=part, t_received_ns=record.log_time))
                elif kind == "sample":
                    rec.samples.setdefault(key, []).append((record.log_time / 1e9, record.data))
                    rec.sample_ns.setdefault(key, []).append(record.log_time)
    return rec


def recover(source: str | Path, out: str | Path) -> dict[str, Any]:
    """Rewrite a (possibly truncated) recording into a complete MCAP file with summary and footer.

    Schemas, channels, metadata and every readable message are copied in order. Returns counts.
    """
    src, dst = Path(source), Path(out)
    if dst.exists():
        raise RecordingError(f"{dst} exists; recover never overwrites", detail={"path": str(dst)})
    schema_map: dict[int, int] = {}
    channel_map: dict[int, int] = {}
    messages = 0
    truncated = False
    with open(dst, "xb") as f:
        w = Writer(f, compression=CompressionType.NONE)
        w.start(profile="", library="objscan-recover")
        for record in iter_records(src):
            if isinstance(record, tuple):
                truncated = bool(record[1])
            elif isinstance(record, Schema):
                schema_map[record.id] = w.register_schema(record.name, record.encoding, record.data)
            elif isinstance(record, Channel):
                channel_map[record.id] = w.register_channel(record.topic, record.message_encoding,
                                                            schema_map.get(record.schema_id, 0), record.metadata)
            elif isinstance(record, Metadata):
                w.add_metadata(record.name, dict(record.metadata))
            elif isinstance(record, Message) and record.channel_id in channel_map:
                w.add_message(channel_id=channel_map[record.channel_id], log_time=record.log_time, data=record.data,
                              publish_time=record.publish_time, sequence=record.sequence)
                messages += 1
        w.finish()
    return {"messages": messages, "channels": len(channel_map), "source_truncated": truncated}
