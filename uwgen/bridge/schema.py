"""Schema announcements: refuse frames of ids whose schema differs from the far side's.

Every TopicCodec/ServiceCodec of a generated package carries `fingerprint` (4 bytes,
see uwgen.codegen.fingerprint). With `schema_id` in the manifest, each bridge announces
the fingerprints of every id of its manifest on that id (the side sending an id learns
too that the far side refuses it), as kind-0 payloads (wire-format.md section 10):

    0, schema_id, flags, id1, fp1, id2, fp2, ...     (a CBOR sequence; flags bit 0: "announce yours")

split over as many payloads as needed to keep each frame within one packet
(max_read_length). It announces at start (queued until the link connects, then sent
ahead of data) and after every reconnect of its link (asking for the far side's, and
asking again at doubling intervals while nothing is heard, as announcements get lost
in collisions); when
the far side asks, at most once per `min_reply_interval` (the larger of 2 s and 20 times
its own air time, so replies take at most 5 % of the link; requests heard in between
get one reply when the interval ends); and every
`period` seconds. Once an id's fingerprint has been heard, frames of that id whose
fingerprint differs from ours are refused before decoding (`accept` is False), counted
per id, and logged once per new disagreement with both values; an id the far side has
not announced (an rmw_desert node never does) is always accepted. So a mismatch costs
zero bytes per message and cannot go unnoticed.

Sans-IO: `SchemaGuard` only sees payloads, a clock and a `send(payload) -> bool`;
`attach_schema` wires one to a bridge's link.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Callable

from uwgen.manifest.model import LinkConfig, LinkPolicy
from uwgen.runtime.clock import SYSTEM_CLOCK, Clock
from uwgen.runtime.wire.codec import KIND_TOPIC, MAX_ID, DecodeError, load_items, pack_items
from uwgen.runtime.wire.framing import MAX_PAYLOAD, OVERHEAD

FLAG_REQUEST = 1            # "announce yours too" (sent after a connect)
MAX_FINGERPRINT = 32        # longest fingerprint a receiver takes (uwgen sends 4 bytes)
MIN_REPLY_INTERVAL = 2.0    # seconds: at most one reply to requests per interval...
REPLY_AIR_SHARE = 0.05      # ...and replies take at most this share of the link's air time
RETRY_FIRST = 2.0           # seconds after a connect before asking again, if nothing was heard
RETRY_CAP = 600.0           # the retry interval doubles up to this (or to the period)
SCHEMA_TICK = 0.25          # seconds between looks at the link (bridge timer)

log = logging.getLogger("uwgen.schema")


class AnnouncementError(ValueError):
    """A payload on the schema id that is not a valid announcement."""


@dataclass(frozen=True)
class Announcement:
    flags: int
    pairs: tuple[tuple[int, bytes], ...]

    @property
    def request(self) -> bool:
        return bool(self.flags & FLAG_REQUEST)


def encode_announcements(schema_id: int, pairs: list[tuple[int, bytes]], request: bool,
                         max_payload: int = MAX_PAYLOAD) -> list[bytes]:
    """The payloads announcing `pairs` (id, fingerprint), in id order, each at most
    `max_payload` bytes (but always at least one pair per payload)."""
    head = [KIND_TOPIC, schema_id, FLAG_REQUEST if request else 0]
    limit = min(max_payload, MAX_PAYLOAD)
    out: list[bytes] = []
    items: list = []
    for ident, fp in sorted(pairs):
        trial = pack_items([*head, *items, ident, fp])
        if items and len(trial) > limit:
            out.append(pack_items([*head, *items]))
            items = []
        items += [ident, fp]
    if items or not out:
        out.append(pack_items([*head, *items]))
    return out


def decode_announcement(payload: bytes, schema_id: int) -> Announcement:
    """Parse one announcement payload; AnnouncementError says what is wrong."""
    try:
        v = load_items(payload)
    except DecodeError as exc:
        raise AnnouncementError(f"not CBOR: {exc}") from None
    if len(v) < 3 or v[0] != KIND_TOPIC or v[1] != schema_id:
        raise AnnouncementError(f"expected kind 0, id {schema_id} and flags, got {v[:3]!r}")
    flags = v[2]
    if type(flags) is not int or flags < 0:
        raise AnnouncementError(f"flags must be an unsigned integer, got {flags!r}")
    rest = v[3:]
    if len(rest) % 2:
        raise AnnouncementError(f"{len(rest)} items after the flags: expected id, fingerprint pairs")
    pairs = []
    for k in range(0, len(rest), 2):
        ident, fp = rest[k], rest[k + 1]
        if type(ident) is not int or not 1 <= ident <= MAX_ID:
            raise AnnouncementError(f"id must be 1..{MAX_ID}, got {ident!r}")
        if type(fp) is not bytes or not 1 <= len(fp) <= MAX_FINGERPRINT:
            raise AnnouncementError(f"fingerprint of id {ident} must be 1..{MAX_FINGERPRINT} bytes, got {fp!r}")
        pairs.append((ident, fp))
    return Announcement(flags, tuple(pairs))


class SchemaGuard:
    """One side's announcements and the far side's fingerprints (see the module doc).

    `ours`: id -> (name, fingerprint) for every id of the manifest; `sends`: the ids
    announced (every id, for a bridge); `send(payload) -> bool` queues an announcement payload;
    `say(level, text)` logs ('info', 'warning', 'error')."""

    def __init__(self, schema_id: int, ours: dict[int, tuple[str, bytes]], sends: list[int],
                 send: Callable[[bytes], bool], *, clock: Clock = SYSTEM_CLOCK,
                 period: float | None = None, max_payload: int = MAX_PAYLOAD,
                 min_reply_interval: float = MIN_REPLY_INTERVAL,
                 connects: Callable[[], int | None] | None = None,
                 queued: Callable[[], int] | None = None,
                 say: Callable[[str, str], None] | None = None, digest: bytes = b""):
        self.schema_id = schema_id
        self.digest = digest
        self.ours = dict(ours)
        self.sends = sorted(i for i in set(sends) if self.ours.get(i, ("", b""))[1])
        self._send = send
        self._clock = clock
        self.period = period
        self.max_payload = max_payload
        self.min_reply_interval = min_reply_interval
        self._connects = connects or (lambda: None)
        self._queued = queued or (lambda: 0)
        self._say = say or (lambda level, text: getattr(log, level)(text))
        self.theirs: dict[int, bytes] = {}
        self.refused: dict[int, int] = {}
        self._reported: dict[int, bytes] = {}        # id -> their fingerprint already logged
        self._unknown: set[int] = set()
        self._last_connects = 0
        self._started = False
        self._last_reply: float | None = None
        self._reply_owed = False
        self._next_periodic: float | None = None
        self._heard = False                 # an announcement arrived since the last connect
        self._retry_gap = RETRY_FIRST
        self._retry_at: float | None = None
        self.counters = {"announcements_sent": 0, "payloads_sent": 0, "send_refused": 0,
                         "announcements_heard": 0, "requests_heard": 0, "bad_announcements": 0}

    # -- sending -------------------------------------------------------------------------

    def payloads(self, request: bool) -> list[bytes]:
        pairs = [(i, self.ours[i][1]) for i in self.sends]
        return encode_announcements(self.schema_id, pairs, request, self.max_payload)

    def announce(self, request: bool = False) -> bool:
        """Queue one announcement (all its payloads); False if the link refused any."""
        ok = True
        for payload in self.payloads(request):
            if self._send(payload):
                self.counters["payloads_sent"] += 1
            else:
                self.counters["send_refused"] += 1
                ok = False
        self.counters["announcements_sent"] += 1
        return ok

    def start(self) -> None:
        """Queue the first announcement (with a request) before the link connects: the
        schema channel's priority sends it ahead of any data once it does."""
        self._started = True
        self.announce(request=True)

    def tick(self, now: float | None = None) -> None:
        """Announce (with a request) after each new connect, and every `period` seconds."""
        now = self._clock.now() if now is None else now
        if self._reply_owed:
            self._reply(now)
        connects = self._connects()
        if connects is not None and connects > self._last_connects:
            first = self._last_connects == 0
            self._last_connects = connects
            if not (first and self._started):   # start() already queued this one
                self.announce(request=True)
            if self.period:
                self._next_periodic = now + self.period
            self._heard = False
            self._retry_gap = max(RETRY_FIRST, self.min_reply_interval)
            self._retry_at = now + self._retry_gap
            return
        if not self._heard and self._retry_at is not None and now >= self._retry_at:
            # Nothing heard since the connect: the announcements may have been lost (or
            # the far side never announces, like rmw_desert): ask again, ever less often.
            self._retry_gap = min(2 * self._retry_gap, self.period or RETRY_CAP)
            self._retry_at = now + self._retry_gap
            if not self._queued():
                self.announce(request=True)
        if self.period and self._last_connects:
            if self._next_periodic is None:
                self._next_periodic = now + self.period
            elif now >= self._next_periodic:
                self._next_periodic = now + self.period
                if not self._queued():      # an identical announcement is still waiting
                    self.announce()

    # -- receiving -----------------------------------------------------------------------

    def is_announcement(self, payload: bytes) -> bool:
        return len(payload) >= 2 and payload[0] == KIND_TOPIC and _second_item(payload) == self.schema_id

    def handle(self, payload: bytes) -> bool:
        """Take `payload` if it is an announcement (kind 0 on the schema id): True then."""
        if not self.is_announcement(payload):
            return False
        try:
            ann = decode_announcement(payload, self.schema_id)
        except AnnouncementError as exc:
            self.counters["bad_announcements"] += 1
            if self.counters["bad_announcements"] == 1:
                self._say("warning", f"schema announcement dropped: {exc} (further ones are "
                                     "counted in ~/status)")
            return True
        self.counters["announcements_heard"] += 1
        self._heard = True
        self._learn(ann.pairs)
        if ann.request:
            self.counters["requests_heard"] += 1
            self._reply_owed = True
            self._reply(self._clock.now())
        return True

    def _reply(self, now: float) -> None:
        """Answer an owed request unless one was answered within `min_reply_interval` (then
        `tick` answers it later: requests coalesce) or an announcement is still queued."""
        if self._last_reply is not None and now - self._last_reply < self.min_reply_interval:
            return
        self._reply_owed = False
        if self._queued():      # the announcement waiting in the link answers it
            return
        self._last_reply = now
        self.announce()

    def register(self, dispatcher: Any) -> None:
        """Take announcements on (0, schema_id) and screen every other payload by id
        (a bridge.dispatch.Dispatcher)."""
        dispatcher.route(KIND_TOPIC, self.schema_id, lambda _ident, payload: self.handle(payload))
        dispatcher.screen(self.accept)

    def accept(self, ident: int) -> bool:
        """False (and counted) when the far side announced a different fingerprint for
        `ident`; True otherwise (also for ids it never announced)."""
        theirs = self.theirs.get(ident)
        if theirs is None:
            return True
        ours = self.ours.get(ident)
        if ours is None or not ours[1] or ours[1] == theirs:
            return True
        self.refused[ident] = self.refused.get(ident, 0) + 1
        return False

    def _learn(self, pairs: tuple[tuple[int, bytes], ...]) -> None:
        differ, agree, unknown = [], [], []
        for ident, fp in pairs:
            self.theirs[ident] = fp
            if ident not in self.ours:
                if ident not in self._unknown:
                    self._unknown.add(ident)
                    unknown.append(ident)
                continue
            name, ours = self.ours[ident]
            if not ours or ours == fp:
                if ident in self._reported:
                    del self._reported[ident]
                    agree.append(f"{name} (id {ident})")
            elif self._reported.get(ident) != fp:
                self._reported[ident] = fp
                differ.append(f"{name} (id {ident}): ours {ours.hex()}, theirs {fp.hex()}")
        if differ:
            self._say("error", "schema mismatch with the far side: frames of these ids are "
                               "refused by whichever side receives them (rebuild both sides "
                               "from the same manifest and definitions): " + "; ".join(differ))
        if agree:
            self._say("info", "schema now agrees with the far side for " + ", ".join(agree))
        if unknown:
            self._say("warning", f"the far side announces ids this manifest does not have: "
                                 f"{sorted(unknown)} (its frames of those ids are dropped as unknown)")

    # -- status --------------------------------------------------------------------------

    def mismatched(self) -> dict[int, dict]:
        out = {}
        for ident, theirs in sorted(self.theirs.items()):
            if ident in self.ours and self.ours[ident][1] and self.ours[ident][1] != theirs:
                name, ours = self.ours[ident]
                out[ident] = {"name": name, "ours": ours.hex(), "theirs": theirs.hex(),
                              "refused": self.refused.get(ident, 0)}
        return out

    def stats(self) -> dict:
        return {"id": self.schema_id, "digest": self.digest.hex(), "period": self.period,
                "announces": self.sends,
                **self.counters,
                "heard": {str(i): fp.hex() for i, fp in sorted(self.theirs.items())},
                "mismatched": {str(i): v for i, v in self.mismatched().items()},
                "refused": sum(self.refused.values()),
                "unknown_ids": sorted(self._unknown)}


def _second_item(payload: bytes) -> int | None:
    """The second CBOR item if it is a small unsigned integer (0..255), else None."""
    b = payload[1]
    if b < 24:
        return b
    if b == 24 and len(payload) >= 3:
        return payload[2]
    return None


# -- bridge wiring ---------------------------------------------------------------------

def logger_say(logger: Any) -> Callable[[str, str], None]:
    """`say` for an rclpy logger: one call site per severity (rclpy refuses a call site
    whose severity changes between calls)."""
    def say(level: str, text: str) -> None:
        if level == "error":
            logger.error(text)
        elif level == "warning":
            logger.warning(text)
        else:
            logger.info(text)
    return say


def channel_policy(parts: int, priorities: list[int]) -> LinkPolicy:
    """Announcements go before data (one above the highest priority) and queue two rounds."""
    return LinkPolicy(queue="fifo", depth=max(2, 2 * parts), priority=max(priorities, default=0) + 1,
                      strict=True)


def whole_payload(link: Any, schema_id: int, link_config: LinkConfig) -> int:
    """The longest announcement payload that leaves in one packet, unfragmented: the link
    says (wire format 2's envelope and any protection take their share); a link that cannot
    say gets a frame of max_read_length."""
    ask = getattr(link, "whole_payload", None)
    return ask(schema_id) if callable(ask) else max(1, link_config.max_read_length - OVERHEAD)


def attach_schema(plan: Any, link: Any, clock: Clock, link_config: LinkConfig,
                  say: Callable[[str, str], None]) -> SchemaGuard | None:
    """A SchemaGuard for a bridge plan with a `schema_id`, its channel added to `link`;
    None when the manifest reserves no schema id."""
    schema_id = getattr(plan, "schema_id", None)
    if schema_id is None:
        return None
    actions = (*getattr(plan, "offered_actions", ()), *getattr(plan, "served_actions", ()))
    ours = {e.id: (e.name, getattr(e, "fingerprint", b""))
            for e in (*plan.topics, *plan.services, *actions)}
    # Entries of other fleet vehicles: known (their announcements are checked, not reported
    # as unknown), never announced by this side.
    known = {**{e.id: (e.name, getattr(e, "fingerprint", b"")) for e in getattr(plan, "overheard", ())},
             **ours}
    channels = plan.channels()

    def link_stats() -> dict:
        try:
            return link.stats()
        except Exception:     # the link is shutting down
            return {}

    def connects() -> int | None:
        value = (link_stats().get("connection") or {}).get("connects")
        return value if isinstance(value, int) else None

    def queued() -> int:
        chans = link_stats().get("channels") or {}
        entry = chans.get(schema_id, chans.get(str(schema_id), {}))
        return int(entry.get("queued", 0)) if isinstance(entry, dict) else 0

    guard = SchemaGuard(schema_id, known, list(ours),
                        lambda payload: link.offer(schema_id, payload), clock=clock,
                        period=getattr(plan, "schema_period", None),
                        max_payload=whole_payload(link, schema_id, link_config),
                        connects=connects, queued=queued, say=say,
                        digest=getattr(plan, "schema_digest", b""))
    air = sum(len(p) + OVERHEAD for p in guard.payloads(False)) / link_config.bytes_per_second
    guard.min_reply_interval = max(MIN_REPLY_INTERVAL, air / REPLY_AIR_SHARE)
    link.add_channel(schema_id, channel_policy(len(guard.payloads(True)),
                                               [p.priority for _, p, _, _ in channels]),
                     "schema announcements")
    say("info", f"schema announcements on id {schema_id}: this side's schema digest is "
                f"{guard.digest.hex() or '-'}; announcing ids {guard.sends or 'none'}")
    return guard
