"""`uwgen bridge --record PATH.mcap`: what crossed this side's link, in one MCAP file.

Channels of a recording (docs/operators.md, "Recordings"):

- each bridged topic under its own name, `cdr` messages with the type's `ros2msg` schema
  (what rosbag2 writes: Foxglove, `ros2 bag` and mcap-ros2-support play them): on the side
  that publishes it, every message the bridge took (publish_time: when its publisher
  published it, from the message's source timestamp); on the other sides, every message the
  bridge published. A message's `sequence` is the CRC-32 of the payload it crossed the link
  as, the same on both sides, which is how `uwgen log` matches them;
- `/uwgen/packets` (json): every packet the link wrote (`tx`, outcome `sent`) or read (`rx`,
  outcome `delivered N`, `fragment`, `control` or `dropped REASON`), with its size and bytes;
- `/uwgen/unheard` (json): the messages published while no subscriber listened (same time
  as the message's record; `uwgen log` does not count them delivered);
- `/uwgen/calls` (json): each call of a bridged service made here (the side that calls it):
  the service, when it was called, when it ended, whether a response came back;
- `/uwgen/status` (json): the bridge's ~/status snapshot, at most every STATUS_EVERY
  seconds as the ~/status and /diagnostics timers compute it, and at exit (the last one has
  the final counts; a recording cut short has those of a few seconds before);
- metadata `uwgen`: network, side, the link's packet size and period.

Times are the system clock's (ns since the epoch; `wall`, injectable), so the two sides'
recordings of one machine, or of two with synchronised clocks, compare directly. All
writing happens on the writer's own thread (uwgen.fieldkit.writer): the link and executor
threads only stamp and queue.
"""
from __future__ import annotations

import binascii
import json
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from uwgen.fieldkit.writer import DEFAULT_KEEP, DEFAULT_MAX_BYTES, RotatingMcap

PACKETS = "/uwgen/packets"
STATUS = "/uwgen/status"
UNHEARD = "/uwgen/unheard"
CALLS = "/uwgen/calls"
STATUS_EVERY = 2.0    # s: the most often a status snapshot is recorded (the final one always)
PACKET_SCHEMA = json.dumps({
    "type": "object", "title": "uwgen packet",
    "properties": {"dir": {"type": "string", "enum": ["tx", "rx"]}, "size": {"type": "integer"},
                   "outcome": {"type": "string"}, "data": {"type": "string"}}})


@dataclass(frozen=True)
class RecordOptions:
    path: Path
    max_bytes: int = DEFAULT_MAX_BYTES
    keep: int = DEFAULT_KEEP


class BridgeRecorder:
    """One side's recording: a link observer, taps for taken and published messages, and
    status snapshots, into a RotatingMcap."""

    def __init__(self, options: RecordOptions, *, network: str, side: str, link_config: Any,
                 topics: dict[str, str], wall: Callable[[], float] = time.time, **writer_kw: Any):
        self.wall = wall
        self.out = RotatingMcap(options.path, max_bytes=options.max_bytes, keep=options.keep,
                                metadata={"uwgen": {
                                    "network": network, "side": side,
                                    "max_read_length": str(link_config.max_read_length),
                                    "period": str(link_config.period),
                                    "topics": json.dumps(topics, sort_keys=True)}},
                                **writer_kw)
        self._packets = self.out.channel(PACKETS, "json", ("uwgen/Packet", "jsonschema", PACKET_SCHEMA))
        self._status = self.out.channel(STATUS, "json", None)
        self._unheard = self.out.channel(UNHEARD, "json", None)
        self._calls = self.out.channel(CALLS, "json", None)
        self._topics: dict[str, tuple[int, Callable[[Any], bytes]]] = {}
        self._status_at = float("-inf")

    def _ns(self) -> int:
        return int(self.wall() * 1e9)

    # -- the link's observer (link thread) --------------------------------------------------

    def packet(self, _now: float, direction: str, data: bytes, outcome: str) -> None:
        record = (f'{{"dir":"{direction}","size":{len(data)},"outcome":"{outcome}",'
                  f'"data":"{binascii.hexlify(data).decode()}"}}')
        self.out.add(self._packets, self._ns(), record.encode())

    # -- messages (executor thread) ---------------------------------------------------------

    def topic(self, name: str, cls: type) -> None:
        """Record messages of `name` (its rclpy class `cls`) from now on."""
        from rclpy.serialization import serialize_message

        from uwgen.fieldkit.msgdef import definition, ros_type_name
        ch = self.out.channel(name, "cdr", (ros_type_name(cls), "ros2msg", definition(cls)))
        self._topics[name] = (ch, serialize_message)

    def message(self, name: str, msg: Any, payload: bytes, published: float | None = None,
                listeners: int | None = None) -> None:
        """A message taken (`published`: its publication time, system clock) or published
        (`listeners`: the subscriptions its publisher had then)."""
        entry = self._topics.get(name)
        if entry is None:
            return
        ch, serialize = entry
        now = self._ns()
        self.out.add(ch, now, serialize(msg), int(published * 1e9) if published else now,
                     zlib.crc32(payload))
        if listeners == 0:
            self.out.add(self._unheard, now, json.dumps({"topic": name}).encode())

    def call(self, service: str, start: float, end: float, ok: bool) -> None:
        """A call of a bridged service on this side: from `start` to `end` (system clock)."""
        record = {"service": service, "start": start, "end": end, "ok": ok}
        self.out.add(self._calls, int(end * 1e9), json.dumps(record).encode())

    def status(self, status: dict, final: bool = False) -> None:
        """A status snapshot: recorded when `final` or STATUS_EVERY seconds after the last."""
        now = self.wall()
        if not final and now - self._status_at < STATUS_EVERY:
            return
        self._status_at = now
        self.out.add(self._status, int(now * 1e9), json.dumps(status, sort_keys=True, default=str).encode())

    def stats(self) -> dict:
        return self.out.stats()

    def close(self) -> None:
        self.out.close()


def recorder_for(plan: Any, options: Any, wall: Callable[[], float] = time.time) -> BridgeRecorder | None:
    """The side's recorder when `options.record` names a file (None otherwise); a file that
    cannot be created is a PlanError (exit 2), said before anything starts."""
    if options.record is None:
        return None
    from uwgen.bridge.plan import PlanError
    try:
        import mcap  # noqa: F401 - said clearly here rather than as an ImportError later
    except ImportError as exc:
        raise PlanError(f"--record needs the `mcap` package ({exc})") from exc
    topics = {c.name: "out" for c in plan.outgoing_topics}
    topics.update({c.name: "in" for c in plan.incoming_topics})
    try:
        return BridgeRecorder(RecordOptions(Path(options.record), options.record_max_bytes,
                                            options.record_keep),
                              network=plan.network, side=plan.side, link_config=options.link,
                              topics=topics, wall=wall)
    except OSError as exc:
        raise PlanError(f"cannot record to {options.record}: {exc.strerror or exc}") from exc
