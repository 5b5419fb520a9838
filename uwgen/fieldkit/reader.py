"""Bridge recordings read back (uwgen.bridge.recorder writes them).

A recording cut short (the bridge killed, the disk full) has no summary and ends inside a
record: it is read chunk by chunk up to its last complete one, and `Recording.end` says
where it stops. A file that is empty, not MCAP, or MCAP of something else is a
`RecordingError` naming the file (`uwgen log` exits 2 on it).
"""
from __future__ import annotations

import io
import json
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

PACKETS = "/uwgen/packets"     # the recorder's channels (uwgen.bridge.recorder)
STATUS = "/uwgen/status"
UNHEARD = "/uwgen/unheard"
CALLS = "/uwgen/calls"
MAGIC = b"\x89MCAP0\r\n"


class RecordingError(Exception):
    """A file that is no readable uwgen recording; the message names it."""


@dataclass
class Packet:
    t: float                 # s since the epoch
    dir: str                 # tx | rx
    size: int
    outcome: str             # sent | delivered N | fragment | control | dropped REASON
    data: bytes


@dataclass
class Message:
    t: float                 # when the bridge took it (sending side) or published it
    published: float         # when its publisher published it (sending side), else t
    crc: int                 # CRC-32 of the payload it crossed the link as
    data: bytes              # CDR
    schema: str              # pkg/msg/Type
    log_ns: int = 0
    heard: bool = True       # published while a subscriber listened (receiving side)


@dataclass
class Recording:
    files: list[Path]
    network: str
    side: str
    max_read_length: int
    period: float
    topics: dict[str, str]                       # name -> "out" (this side publishes) | "in"
    packets: list[Packet] = field(default_factory=list)
    messages: dict[str, list[Message]] = field(default_factory=dict)
    statuses: list[tuple[float, dict]] = field(default_factory=list)
    schemas: dict[str, tuple[str, str, bytes]] = field(default_factory=dict)  # topic -> (name, enc, text)
    ends: list[str] = field(default_factory=list)   # how each cut-short file ends
    unheard: set[tuple[str, int]] = field(default_factory=set)   # (topic, log ns) nobody heard
    calls: list[dict] = field(default_factory=list)  # service calls made here: service, start, end, ok

    @property
    def status(self) -> dict:
        """The last status recorded (the final one unless the bridge was cut short)."""
        return self.statuses[-1][1] if self.statuses else {}

    @property
    def span(self) -> tuple[float, float] | None:
        times = [p.t for p in self.packets] + [m.t for ms in self.messages.values() for m in ms]
        return (min(times), max(times)) if times else None


def clock(t: float) -> str:
    return datetime.fromtimestamp(t, timezone.utc).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + " UTC"


def read_file(path: Path) -> Recording:
    """One file of a recording (RecordingError when it is not one)."""
    from mcap.records import Channel, Chunk, DataEnd, Footer, Message as McapMessage, Metadata, Schema
    from mcap.stream_reader import StreamReader, breakup_chunk

    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    if not raw:
        raise RecordingError(f"{path}: empty file, not an MCAP recording")
    if not raw.startswith(MAGIC):
        raise RecordingError(f"{path}: not an MCAP file (it starts with {raw[:8]!r})")
    stream = io.BytesIO(raw)
    reader = StreamReader(stream, emit_chunks=True, record_size_limit=len(raw))
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    meta: dict[str, str] | None = None
    rec = Recording([path], "", "", 0, 0.0, {})
    complete, last_good, last_time, chunks = False, 0, None, 0

    def take(record) -> None:
        nonlocal meta, last_time
        if isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Metadata) and record.name == "uwgen":
            meta = dict(record.metadata)
        elif isinstance(record, McapMessage):
            _message(rec, channels, schemas, record, path)
            last_time = record.log_time / 1e9

    try:
        for record in reader.records:
            if isinstance(record, Chunk):
                inner = breakup_chunk(record, validate_crc=True)   # whole, or not at all
                for r in inner:
                    take(r)
                chunks += 1
            else:
                take(record)
            last_good = stream.tell()
            if isinstance(record, (DataEnd, Footer)):
                complete = True
    except RecordingError:
        raise
    except Exception as exc:  # noqa: BLE001 - any damage past the last complete record
        if meta is None and not chunks:
            raise RecordingError(f"{path}: cut short before anything was recorded "
                                 f"({len(raw)} bytes, {type(exc).__name__})") from exc
        rec.ends.append(f"{path}: cut short; read up to its last complete chunk ({chunks} chunks, "
                        f"byte {last_good} of {len(raw)}), ending at "
                        f"{clock(last_time) if last_time else 'its start'}")
        complete = True
    if meta is None:
        raise RecordingError(f"{path}: an MCAP file but not a uwgen bridge recording "
                             "(no 'uwgen' metadata)")
    for topic, msgs in rec.messages.items():
        for m in msgs:
            m.heard = (topic, m.log_ns) not in rec.unheard
    if not complete:
        rec.ends.append(f"{path}: ends without its summary after {chunks} chunks"
                        + (f", at {clock(last_time)}" if last_time else ""))
    try:
        rec.network, rec.side = meta["network"], meta["side"]
        rec.max_read_length, rec.period = int(meta["max_read_length"]), float(meta["period"])
        rec.topics = json.loads(meta["topics"])
    except (KeyError, ValueError) as exc:
        raise RecordingError(f"{path}: its 'uwgen' metadata is incomplete ({exc})") from exc
    return rec


def _message(rec: Recording, channels: dict, schemas: dict, m, path: Path) -> None:
    ch = channels.get(m.channel_id)
    if ch is None:
        return
    t = m.log_time / 1e9
    if ch.topic == PACKETS:
        d = json.loads(m.data)
        rec.packets.append(Packet(t, d["dir"], int(d["size"]), d["outcome"], bytes.fromhex(d["data"])))
    elif ch.topic == STATUS:
        rec.statuses.append((t, json.loads(m.data)))
    elif ch.topic == CALLS:
        rec.calls.append(json.loads(m.data))
    elif ch.topic == UNHEARD:
        rec.unheard.add((json.loads(m.data)["topic"], m.log_time))
    else:
        schema = schemas.get(ch.schema_id)
        name = schema.name if schema is not None else ""
        if schema is not None:
            rec.schemas.setdefault(ch.topic, (schema.name, schema.encoding, schema.data))
        rec.messages.setdefault(ch.topic, []).append(
            Message(t, m.publish_time / 1e9, m.sequence, m.data, name, m.log_time))


def read_recordings(paths: list[Path]) -> list[Recording]:
    """The files given, one Recording per side (rotated files of a side merged in time order)."""
    by_side: dict[tuple[str, str], Recording] = {}
    for path in paths:
        one = read_file(path)
        key = (one.network, one.side)
        if key not in by_side:
            by_side[key] = one
            continue
        into = by_side[key]
        into.files += one.files
        into.packets += one.packets
        for topic, msgs in one.messages.items():
            into.messages.setdefault(topic, []).extend(msgs)
        into.statuses += one.statuses
        into.calls += one.calls
        into.ends += one.ends
        into.schemas.update(one.schemas)
    for rec in by_side.values():
        rec.packets.sort(key=lambda p: p.t)
        rec.statuses.sort(key=lambda s: s[0])
        for msgs in rec.messages.values():
            msgs.sort(key=lambda m: m.t)
    networks = {n for n, _ in by_side}
    if len(networks) > 1:
        raise RecordingError(f"recordings of different networks: {', '.join(sorted(networks))}")
    return sorted(by_side.values(), key=lambda r: r.side)
