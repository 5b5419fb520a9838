"""Schema announcements and refusal of frames whose schema differs (sans-IO, manual clock)."""
from __future__ import annotations

import pytest

from uwgen.bridge.schema import (
    FLAG_REQUEST, AnnouncementError, SchemaGuard, decode_announcement, encode_announcements,
)
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.codec import load_items, pack_items

SID = 249
FP_CMD, FP_POSE, FP_SRV = bytes.fromhex("11223344"), bytes.fromhex("55667788"), bytes.fromhex("99aabbcc")
OURS = {4: ("/cmd_vel", FP_CMD), 5: ("/pose", FP_POSE), 20: ("/enable", FP_SRV)}


class Harness:
    """A guard with a manual clock, a recording `send`, a settable connect count."""

    def __init__(self, sends=(4, 20), period=None, ours=OURS, max_payload=250):
        self.clock = ManualClock(100.0)
        self.sent: list[bytes] = []
        self.logs: list[tuple[str, str]] = []
        self.connects = 0
        self.queued = 0
        self.guard = SchemaGuard(SID, ours, list(sends), self._send, clock=self.clock,
                                 period=period, max_payload=max_payload,
                                 connects=lambda: self.connects, queued=lambda: self.queued,
                                 say=lambda level, text: self.logs.append((level, text)))

    def _send(self, payload: bytes) -> bool:
        self.sent.append(payload)
        return True

    def take_sent(self) -> list:
        out = [decode_announcement(p, SID) for p in self.sent]
        self.sent.clear()
        return out


def announcement(*pairs, request=False) -> bytes:
    return pack_items([0, SID, FLAG_REQUEST if request else 0, *[x for p in pairs for x in p]])


# --- the payload ---------------------------------------------------------------------

def test_announcement_round_trips_and_is_ordered_by_id():
    [payload] = encode_announcements(SID, [(20, FP_SRV), (4, FP_CMD)], request=True)
    assert load_items(payload) == [0, SID, 1, 4, FP_CMD, 20, FP_SRV]
    ann = decode_announcement(payload, SID)
    assert ann.request and ann.pairs == ((4, FP_CMD), (20, FP_SRV))


def test_announcement_is_split_to_fit_the_packet():
    pairs = [(i, bytes([i] * 4)) for i in range(1, 41)]
    payloads = encode_announcements(SID, pairs, request=False, max_payload=60)
    assert len(payloads) > 1 and all(len(p) <= 60 for p in payloads)
    heard = [pair for p in payloads for pair in decode_announcement(p, SID).pairs]
    assert heard == pairs


def test_one_pair_per_payload_when_the_packet_is_tiny():
    payloads = encode_announcements(SID, [(4, FP_CMD), (5, FP_POSE)], request=False, max_payload=3)
    assert [decode_announcement(p, SID).pairs for p in payloads] == [((4, FP_CMD),), ((5, FP_POSE),)]


@pytest.mark.parametrize("payload, why", [
    (b"\xff", "not CBOR"),
    (pack_items([0, SID]), "expected kind 0, id 249 and flags"),
    (pack_items([0, SID, -1]), "flags must be an unsigned integer"),
    (pack_items([0, SID, 0, 4]), "1 items after the flags"),
    (pack_items([0, SID, 0, 0, FP_CMD]), "id must be 1..255"),
    (pack_items([0, SID, 0, 4, "abcd"]), "fingerprint of id 4 must be 1..32 bytes"),
    (pack_items([0, SID, 0, 4, b""]), "fingerprint of id 4 must be 1..32 bytes"),
])
def test_malformed_announcements_are_refused_with_a_reason(payload, why):
    with pytest.raises(AnnouncementError, match=why):
        decode_announcement(payload, SID)


# --- refusing --------------------------------------------------------------------------

def test_nothing_is_refused_before_the_far_side_announces():
    h = Harness()
    assert all(h.guard.accept(i) for i in (4, 5, 20, 77))
    assert h.guard.refused == {}


def test_a_differing_id_is_refused_counted_and_logged_once_with_both_values():
    h = Harness()
    other = bytes.fromhex("deadbeef")
    assert h.guard.handle(announcement((4, other), (5, FP_POSE)))
    assert not h.guard.accept(4) and not h.guard.accept(4)
    assert h.guard.accept(5)                  # announced and equal
    assert h.guard.accept(20)                 # never announced by the far side
    assert h.guard.refused == {4: 2}
    assert h.guard.handle(announcement((4, other)))   # heard again: no second log line
    errors = [text for level, text in h.logs if level == "error"]
    assert len(errors) == 1
    assert "/cmd_vel (id 4): ours 11223344, theirs deadbeef" in errors[0] and "/pose" not in errors[0]
    status = h.guard.stats()
    assert status["mismatched"] == {"4": {"name": "/cmd_vel", "ours": "11223344", "theirs": "deadbeef",
                                          "refused": 2}}
    assert status["refused"] == 2 and status["heard"]["5"] == FP_POSE.hex()


def test_agreement_after_a_rebuild_accepts_again():
    h = Harness()
    h.guard.handle(announcement((4, b"\x00\x00\x00\x01")))
    assert not h.guard.accept(4)
    h.guard.handle(announcement((4, FP_CMD)))
    assert h.guard.accept(4) and h.guard.stats()["mismatched"] == {}
    assert ("info", "schema now agrees with the far side for /cmd_vel (id 4)") in h.logs


def test_a_new_different_value_is_logged_again():
    h = Harness()
    h.guard.handle(announcement((4, b"\x00\x00\x00\x01")))
    h.guard.handle(announcement((4, b"\x00\x00\x00\x02")))
    assert sum(level == "error" for level, _ in h.logs) == 2


def test_ids_unknown_here_are_reported_once_and_not_refused():
    h = Harness()
    h.guard.handle(announcement((77, FP_CMD)))
    h.guard.handle(announcement((77, FP_CMD)))
    assert h.guard.accept(77)
    assert [level for level, _ in h.logs] == ["warning"] and "[77]" in h.logs[0][1]
    assert h.guard.stats()["unknown_ids"] == [77]


def test_other_payloads_are_not_taken():
    h = Harness()
    assert not h.guard.handle(pack_items([0, 4, 1.5]))
    assert not h.guard.handle(pack_items([2, SID, 7, 1]))          # a request on that id
    assert h.guard.counters["announcements_heard"] == 0


def test_a_malformed_announcement_is_consumed_counted_and_logged_once():
    h = Harness()
    assert h.guard.handle(pack_items([0, SID, 0, 4]))
    assert h.guard.handle(pack_items([0, SID, "x"]))
    assert h.guard.counters["bad_announcements"] == 2
    assert len(h.logs) == 1 and h.logs[0][0] == "warning"
    assert h.guard.accept(4)


# --- announcing --------------------------------------------------------------------------

def test_announces_its_ids_with_a_request_after_each_connect():
    h = Harness(sends=(4, 20))
    h.guard.tick()
    assert h.sent == []                                   # not connected yet
    h.connects = 1
    h.guard.tick()
    [ann] = h.take_sent()
    assert ann.request and ann.pairs == ((4, FP_CMD), (20, FP_SRV))   # the ids it was given
    h.clock.advance(1)
    h.guard.tick()
    assert h.sent == []                                   # no period, no retry yet: nothing more
    h.connects = 2                                        # reconnected
    h.guard.tick()
    assert [a.request for a in h.take_sent()] == [True]


def test_start_queues_the_first_announcement_and_the_first_connect_adds_none():
    h = Harness()
    h.guard.start()
    assert [a.request for a in h.take_sent()] == [True]
    h.connects = 1
    h.guard.tick()
    assert h.sent == []
    h.connects = 2
    h.guard.tick()
    assert [a.request for a in h.take_sent()] == [True]


def test_periodic_announcements_follow_the_manifest_period():
    h = Harness(period=600.0)
    h.connects = 1
    h.guard.tick()
    h.take_sent()
    h.guard.handle(announcement((5, FP_POSE)))            # heard: no retries
    h.clock.advance(599)
    h.guard.tick()
    assert h.sent == []
    h.clock.advance(1)
    h.guard.tick()
    [ann] = h.take_sent()
    assert not ann.request
    h.clock.advance(600)
    h.queued = 1                                          # the last one has not left yet
    h.guard.tick()
    assert h.sent == []


def test_requests_are_answered_at_most_once_per_interval_and_coalesce():
    h = Harness()
    h.guard.handle(announcement((5, FP_POSE), request=True))
    [reply] = h.take_sent()
    assert not reply.request and reply.pairs == ((4, FP_CMD), (20, FP_SRV))
    h.clock.advance(0.5)
    h.guard.handle(announcement((5, FP_POSE), request=True))
    h.clock.advance(0.5)
    h.guard.handle(announcement((5, FP_POSE), request=True))
    h.guard.tick()
    assert h.sent == []                                   # within 2 s of the last reply
    h.clock.advance(1.0)
    h.guard.tick()
    assert len(h.take_sent()) == 1                        # both requests, one reply
    h.clock.advance(10)
    h.guard.tick()
    assert h.sent == []                                   # nothing owed any more
    assert h.guard.counters["requests_heard"] == 3


def test_asks_again_at_doubling_intervals_until_the_far_side_is_heard():
    h = Harness(period=20.0)
    h.connects = 1
    h.guard.tick()                                        # t=100: connect, announce + request
    h.take_sent()
    times = []
    for _ in range(80):                                   # 40 s in 0.5 s steps
        h.clock.advance(0.5)
        h.guard.tick()
        for ann in h.take_sent():
            times.append((round(h.clock.now() - 100, 1), ann.request))
    # Retries at +2, +6 (gap 4), +14 (gap 8), then the period's pace (gap capped at 20):
    # +20 is the periodic one (no request), +30 the next retry, +40 the next periodic.
    assert times[:4] == [(2.0, True), (6.0, True), (14.0, True), (20.0, False)]
    assert (30.0, True) in times
    h.guard.handle(announcement((5, FP_POSE)))            # heard now
    h.clock.advance(100)
    h.guard.tick()
    assert all(not a.request for a in h.take_sent())      # only the periodic one from now on
    h.connects = 2                                        # a reconnect starts over
    h.guard.tick()
    h.take_sent()
    h.clock.advance(2)
    h.guard.tick()
    assert [a.request for a in h.take_sent()] == [True]


def test_a_request_is_answered_by_the_announcement_still_queued():
    h = Harness()
    h.queued = 1
    h.guard.handle(announcement((5, FP_POSE), request=True))
    h.guard.tick()
    assert h.sent == []


def test_reply_interval_keeps_replies_under_five_percent_of_a_slow_link():
    from types import SimpleNamespace

    from uwgen.bridge.schema import attach_schema
    from uwgen.manifest.model import LinkConfig, LinkPolicy

    class Link:
        def __init__(self):
            self.channels = {}

        def add_channel(self, key, policy, name=None):
            self.channels[key] = policy

        def offer(self, key, payload):
            return True

        def stats(self):
            return {}

    entries = [SimpleNamespace(id=i, name=f"/t{i}", fingerprint=bytes(4)) for i in (3, 4, 5)]
    plan = SimpleNamespace(schema_id=SID, schema_period=None, schema_digest=b"\x01\x02\x03\x04",
                           topics=entries, services=[],
                           channels=lambda: [(e.id, LinkPolicy(priority=7), e.name, False) for e in entries])
    link = Link()
    logs = []
    slow = attach_schema(plan, link, ManualClock(), LinkConfig(max_read_length=32, period=1.0),
                         lambda level, text: logs.append(text))
    # 26-byte frame on a 32 B/s link: 0.81 s of air time, so one reply per 16.25 s at most.
    assert slow.min_reply_interval == 26 / 32 / 0.05
    assert link.channels[SID].priority == 8 and link.channels[SID].queue == "fifo"
    assert "schema digest is 01020304; announcing ids [3, 4, 5]" in logs[0]   # every id
    fast = attach_schema(plan, Link(), ManualClock(), LinkConfig(max_read_length=64, period=0.05),
                         lambda level, text: None)
    assert fast.min_reply_interval == 2.0


def test_ids_without_a_fingerprint_are_not_announced():
    h = Harness(sends=(4, 20), ours={**OURS, 20: ("/enable", b"")})
    h.connects = 1
    h.guard.tick()
    assert h.take_sent()[0].pairs == ((4, FP_CMD),)


def test_logger_say_takes_every_severity_from_one_rclpy_logger():
    # rclpy refuses one call site logging at two severities ("Logger severity cannot be
    # changed between calls"); a mismatch after an info line must not raise.
    from rclpy.logging import get_logger

    from uwgen.bridge.schema import logger_say
    say = logger_say(get_logger("uwgen_schema_test"))
    for level in ("info", "error", "warning", "info", "error"):
        say(level, f"{level} line")


def test_registered_on_a_dispatcher_it_takes_announcements_and_screens_other_ids():
    from uwgen.bridge.counters import BridgeCounters
    from uwgen.bridge.dispatch import Dispatcher

    h = Harness()
    dispatcher = Dispatcher(BridgeCounters())
    got = []
    dispatcher.route(0, 4, lambda ident, payload: got.append(ident))
    dispatcher.route(0, 5, lambda ident, payload: got.append(ident))
    h.guard.register(dispatcher)
    dispatcher.dispatch(announcement((4, b"\x00\x00\x00\x09"), (5, FP_POSE)))
    dispatcher.dispatch(pack_items([0, 4, 1.0]))
    dispatcher.dispatch(pack_items([0, 5, 1.0]))
    assert got == [5]                                    # 4 refused before its handler ran
    assert h.guard.counters["announcements_heard"] == 1 and h.guard.refused == {4: 1}
    assert dispatcher.counters.unknown_id == 0


# --- properties ----------------------------------------------------------------------------

from hypothesis import given, settings, strategies as st  # noqa: E402


@settings(max_examples=200, deadline=None)
@given(pairs=st.dictionaries(st.integers(1, 255), st.binary(min_size=1, max_size=32), max_size=60),
       request=st.booleans(), schema_id=st.integers(1, 255), max_payload=st.integers(1, 300))
def test_split_announcements_carry_every_pair_once(pairs, request, schema_id, max_payload):
    payloads = encode_announcements(schema_id, list(pairs.items()), request, max_payload)
    heard = []
    for p in payloads:
        ann = decode_announcement(p, schema_id)
        assert ann.request == request
        assert len(p) <= max(max_payload, 3 + 2 + 2 + 34) and len(p) <= 255
        heard += ann.pairs
    assert heard == sorted(pairs.items())


@settings(max_examples=300, deadline=None)
@given(payload=st.binary(max_size=80))
def test_any_bytes_on_the_schema_id_are_taken_or_refused_never_crash(payload):
    h = Harness()
    data = bytes([0x00, 0x18, SID]) + payload
    assert h.guard.handle(data)                          # kind 0 on the schema id: taken
    assert h.guard.counters["announcements_heard"] + h.guard.counters["bad_announcements"] == 1
    for ident in range(1, 30):
        h.guard.accept(ident)


# --- announcements fit one packet ---------------------------------------------------------

@pytest.mark.parametrize("wire, signed", [(1, False), (2, False), (2, True)])
def test_announcements_sized_by_the_link_each_leave_in_one_packet_unfragmented(wire, signed):
    from uwgen.bridge.schema import whole_payload
    from uwgen.emulator import NodeSpec, Scenario
    from uwgen.emulator.linksim import LinkSim
    from uwgen.manifest.model import LinkConfig, LinkPolicy
    from uwgen.runtime.wire.framing import ShortFrameDecoder
    from uwgen.security.guard import GuardConfig, LinkGuard

    scen = Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                           NodeSpec("b", position=(300, 0, 0), dest="a")],
                    period=0.2, max_read_length=64, seed=1, bitrate=4800.0)
    kw = dict(wire_format=wire, sender_id=1) if wire == 2 else {}
    if signed:
        kw["guard"] = LinkGuard(bytes(32), GuardConfig("n", 1, {2: "b"}, {SID: "sign"}), name="a")
    sim = LinkSim(scen, "a", "b", fragment_id=250, **kw)
    link = sim.sender
    link.add_channel(SID, LinkPolicy(queue="fifo", depth=20))
    size = whole_payload(link, SID, LinkConfig(max_read_length=64, period=0.2))
    pairs = [(i, bytes([i] * 4)) for i in range(3, 40)]
    payloads = encode_announcements(SID, pairs, request=True, max_payload=size)
    assert len(payloads) > 1
    for p in payloads:
        assert link.offer(SID, p)
    sim.run(len(payloads) * 0.25 + 1.0)
    assert link.scheduler.stats()[SID]["fragments_sent"] == 0
    assert len(sim.packets) == len(payloads)          # one packet each, none cut or fragmented
    assert all(len(d.data) <= 64 and ShortFrameDecoder().feed(d.data) for d in sim.packets)
    # as large as that allows: one more pair would not have fitted
    assert max(len(p) for p in payloads) > size - 6
