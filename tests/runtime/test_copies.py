"""Copies in spare room (docs/wire-format.md section 15.6): once the measured loss is above 1
packet in 20, a reliable message not acknowledged yet also rides in the room a later packet,
which leaves anyway with fresh messages, has left (a second copy from 1 packet in 10, a third
from 3 in 20, the message with the fewest copies first); a lost copy is sent again only when no
other copy is on its way or has arrived; the receiver delivers it once and the ledger counts
every copy. Every time is explicit (the engine) or a ManualClock (the packer, the links)."""
from __future__ import annotations

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.duplex import DuplexSim
from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.clock import ManualClock
from types import SimpleNamespace

from uwgen.runtime.delivery.copies import (COPY_LOSS, LOSS_WINDOW, SECOND_COPY_LOSS,
                                           THIRD_COPY_LOSS, Copies)
from uwgen.runtime.delivery.reliability import Reliability
from uwgen.runtime.delivery.reliable import ReliableLink, RttEstimator, Sent
from uwgen.runtime.link.hooks import PacketHooks
from uwgen.runtime.link.packets import PACKET_COUNTERS, Packer
from uwgen.runtime.stats import Counters
from uwgen.runtime.wire import envelope

SURFACE, VEHICLE = 1, 2
EPOCH = b"\x01" * 6


def engine(me: int) -> ReliableLink:
    return ReliableLink(me, RttEstimator(6.0, 1.0, 60.0, 0.5), ack_delay=2.0, bitmap_bytes=1)


# -- the engine (explicit times) ------------------------------------------------------------

def test_a_lost_copy_is_not_sent_again_when_another_copy_arrived():
    s, r = engine(SURFACE), engine(VEHICLE)
    s.sent(0, [Sent(8, "mission", 30.0, ident=0)], 0.0)               # lost
    s.sent(1, [Sent(4, "cmd", None), Sent(8, "mission", 30.0, ident=0)], 0.2)   # its copy
    r.received(SURFACE, EPOCH, 1, 0.9, eliciting=True)
    s.acked(r.ack_for(SURFACE, 1.0), 1.7)
    assert s.due(1.7) == [] and s.fast_resends == 0
    assert (s.ledger[8].sent, s.ledger[8].delivered, s.ledger[8].lost_on_link) == (2, 1, 1)


def test_a_lost_copy_waits_for_the_fate_of_the_other_one_on_its_way():
    s, r = engine(SURFACE), engine(VEHICLE)
    s.sent(0, [Sent(8, "mission", 30.0, ident=0)], 0.0)               # lost
    s.sent(1, [Sent(4, "cmd", None)], 0.2)
    s.sent(2, [Sent(8, "mission", 30.0, ident=0)], 0.4)               # its copy: lost too
    r.received(SURFACE, EPOCH, 1, 0.9, eliciting=False)
    s.acked(r.ack_for(SURFACE, 1.0), 1.7)                              # 0 lost, 2 unknown yet
    assert s.due(1.7) == []
    r.received(SURFACE, EPOCH, 3, 2.0, eliciting=False)
    s.sent(3, [Sent(4, "cmd", None)], 1.8)
    s.acked(r.ack_for(SURFACE, 2.1), 2.8)                              # 2 lost: none left
    assert [m.ref for m in s.due(2.8)] == ["mission"] and s.fast_resends == 1


def test_the_measured_loss_counts_the_last_packets_the_peer_reported():
    s, r = engine(SURFACE), engine(VEHICLE)
    for n in range(LOSS_WINDOW):
        s.sent(n, [Sent(4, "cmd", None)], 0.1 * n)
        if n % 8:                                                      # 1 in 8 lost
            r.received(SURFACE, EPOCH, n, 0.1 * n + 0.7, eliciting=False)
    assert s.spare.loss() == 0.0                                             # nothing reported yet
    s.acked(r.ack_for(SURFACE, 10.0, nbytes=LOSS_WINDOW // 8), 10.5)
    assert s.spare.loss() == LOSS_WINDOW // 8 / LOSS_WINDOW


def measured(lost: int) -> Copies:
    """Copies whose last LOSS_WINDOW settled packets had `lost` reported missing."""
    c = Copies()
    for n in range(LOSS_WINDOW):
        c.settled(n >= lost)
    return c


def on_their_way(*idents: int) -> list:
    """Packets sent, oldest first, each carrying one reliable message."""
    return [SimpleNamespace(timed_out=False, messages=[Sent(8, f"m{i}", 30.0, ident=i)])
            for i in idents]


def copies_of(c: Copies, packets: list, tries: int = 6) -> list[str]:
    out = []
    for _ in range(tries):
        got = c.pick(packets, 1.0, lambda m: m.ref)
        if got is not None:
            out.append(got[1])
    return out


def test_from_one_packet_in_ten_lost_a_message_gets_a_second_copy():
    few = int(COPY_LOSS * LOSS_WINDOW) + 1                      # 1 in 20 or more, below 1 in 10
    many = -(-int(SECOND_COPY_LOSS * LOSS_WINDOW * 10) // 10)    # 1 in 10 or more
    assert COPY_LOSS <= few / LOSS_WINDOW < SECOND_COPY_LOSS <= many / LOSS_WINDOW
    assert copies_of(measured(few), on_their_way(0)) == ["m0"]
    assert copies_of(measured(many), on_their_way(0)) == ["m0", "m0"]
    assert copies_of(measured(0), on_their_way(0)) == []


def test_from_three_packets_in_twenty_lost_a_message_gets_a_third_copy():
    below = -(-int(THIRD_COPY_LOSS * LOSS_WINDOW * 10) // 10) - 1     # just under 3 in 20
    assert SECOND_COPY_LOSS <= below / LOSS_WINDOW < THIRD_COPY_LOSS
    assert copies_of(measured(below), on_their_way(0)) == ["m0", "m0"]
    # at 20 % the message and its copies are all lost 1 time in 625, not 1 in 125
    assert copies_of(measured(LOSS_WINDOW // 5), on_their_way(0)) == ["m0", "m0", "m0"]


def test_a_message_not_copied_yet_goes_before_a_further_copy_and_the_older_first():
    c = measured(LOSS_WINDOW // 5)                               # 20 %: three copies each
    packets = on_their_way(0, 1)                                 # 1 is the newer
    assert copies_of(c, packets, tries=1) == ["m0"]              # it waited longer
    assert copies_of(c, packets, tries=1) == ["m1"]              # not m0's second copy
    assert copies_of(c, packets) == ["m0", "m1", "m0", "m1"]


def sent_once(loss: int = LOSS_WINDOW // 5) -> Reliability:
    """A side whose loss is measured and round trip known (1.8 s) that sent a packet at
    t=9.8 (number 0), then, at t=10, one reliable message (packet 1), no copy of it yet."""
    rel = Reliability(SURFACE, period=0.2, reliable={8: 30.0}, max_ages={}, name="surface")
    for n in range(LOSS_WINDOW):
        rel.engine.spare.settled(n >= loss)
    rel.engine.rtt.sample(1.8)
    rel.engine.sent(0, [Sent(4, b"\x00\x04c", None)], 9.8)
    rel.engine.sent(1, [Sent(8, b"\x00\x08m0", None, ident=rel.engine.spare.new_ident())], 10.0)
    return rel


def test_a_message_sent_once_whose_report_is_overdue_goes_first_in_the_next_packet():
    rel = sent_once()
    assert rel.resend(11.0, 64) is None                     # its report may still come
    assert rel.resend(11.9, 64) == (8, b"\x00\x08m0")      # a round trip without: first
    assert rel.resend(12.0, 64) is None                     # once; more copies in spare room
    assert rel.copy(12.0, 64) == (8, b"\x00\x08m0")


def test_a_message_whose_report_came_or_that_has_a_copy_waits_for_spare_room():
    rel = sent_once()
    r = engine(VEHICLE)
    r.received(SURFACE, EPOCH, 0, 10.5, eliciting=False)     # built before packet 1 came
    rel.engine.acked(r.ack_for(SURFACE, 10.6, nbytes=0), 11.0)
    assert 1 in rel.engine.outstanding and rel.resend(12.5, 64) is None
    rel = sent_once()
    assert rel.copy(10.2, 64) is not None                   # copied in spare room
    assert rel.resend(12.5, 64) is None
    assert sent_once(loss=0).resend(12.5, 64) is None       # no loss measured: no copies


# -- the packer: copies only in room a packet leaves with anyway ----------------------------

class Queue:
    def __init__(self, items):
        self.items = list(items)

    def next_payload(self, now, budget=None, exclude=None, *, fill=False, cut=None, **_):
        if not self.items or cut is not None or (budget is not None and len(self.items[0]) > budget):
            return None
        return self.items.pop(0)


def packer(fresh, copies, ack_only=True):
    asked = []

    def copy(now, room, fresh):
        asked.append((room, fresh))
        return copies.pop(0) if copies else None
    hooks = PacketHooks(copy=copy, ack_only=lambda now: ack_only)
    return Packer(Queue(fresh), sender=1, max_read_length=64, hooks=hooks,
                  counters=Counters(PACKET_COUNTERS)), asked


def test_a_copy_fills_the_room_left_after_the_fresh_messages():
    p, asked = packer([(4, bytes((0, 4)) + bytes(20))], [(8, bytes((0, 8)) + bytes(20))])
    out = envelope.decode(p.next_packet(0.0))
    assert [m.id for m in out.messages] == [4, 8]                      # fresh first, then the copy
    assert asked and asked[0][0] < 64 and asked[0][1] is True


def test_a_copy_never_makes_a_packet_of_its_own():
    p, asked = packer([], [(8, bytes((0, 8)) + bytes(20))], ack_only=False)
    assert p.next_packet(0.0) is None and asked == []                  # nothing makes it leave


def test_a_packet_that_leaves_for_its_parts_alone_is_offered_copies_as_not_fresh():
    p, asked = packer([], [])
    envelope.decode(p.next_packet(0.0))                                # leaves for its A part
    assert [fresh for _room, fresh in asked] == [False]


def test_reliable_copies_ride_only_beside_fresh_messages():
    rel = Reliability(1, period=0.5, reliable={7: 30.0}, max_ages={}, max_read_length=64)
    for _ in range(LOSS_WINDOW):
        rel.engine.spare.settled(False)                                # lossy: copies wanted
    rel.sent(0, [(7, rel.stamp(7, bytes((0, 7)) + bytes(8), 0.0, 0.0))], 0.0)
    assert rel.copy(0.2, 60, fresh=False) is None
    assert rel.copy(0.2, 60, fresh=True) is not None


# -- two links (a ManualClock) --------------------------------------------------------------

RELIABLE = LinkPolicy(queue="fifo", depth=20, ttl=30.0, reliable=True)
BEST_EFFORT = LinkPolicy(queue="fifo", depth=100, ttl=30.0)


def duplex():
    scen = Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                           NodeSpec("b", position=(300, 0, 0), dest="a")],
                    period=0.5, max_read_length=64, bitrate=4800.0)
    clock = ManualClock()
    rel = {}

    def hooks_for(side):
        rel[side] = Reliability(1 if side == "a" else 2, period=0.5, reliable={7: 30.0},
                                max_ages={7: 30.0}, wall=clock, name=side, max_read_length=64)
        return rel[side].hooks()
    sim = DuplexSim(scen, ("a", "b"), hooks_for=hooks_for, wire_format=2, clock=clock)
    carried = []                                   # a's packets: the reliable messages in each
    sent = sim.links["a"].hooks.sent

    def spy(number, picked, now):
        carried.append([rel["a"].heads.take(p).payload[2] for k, p in picked if k == 7])
        return sent(number, picked, now)
    sim.links["a"].hooks.sent = spy
    a, b = sim.links["a"], sim.links["b"]
    a.add_channel(7, RELIABLE)
    a.add_channel(4, BEST_EFFORT)
    b.add_channel(5, BEST_EFFORT)
    for i in range(60):                            # a steady best-effort stream both ways
        sim.at(0.5 * i, lambda i=i: a.offer(4, bytes((0, 4, i)) + bytes(8)))
        sim.at(0.5 * i + 0.2, lambda i=i: b.offer(5, bytes((0, 5, i)) + bytes(8)))
    return sim, rel, carried


def reliable_at(sim, at: float, k: int = 0):
    sim.at(at, lambda: sim.links["a"].offer(7, bytes((0, 7, k)) + bytes(10)))


def test_with_loss_measured_a_reliable_message_rides_again_in_spare_room_and_arrives_once():
    sim, rel, carried = duplex()
    lost = int(COPY_LOSS * LOSS_WINDOW) + 1
    sim.drop("a", *range(2, 2 + lost))             # early best-effort packets: loss measured
    reliable_at(sim, 15.0)
    sim.run(40.0)
    assert rel["a"].engine.spare.loss() >= COPY_LOSS
    assert sum(ks.count(0) for ks in carried) == 2                     # the message and a copy
    assert [p[2] for _, p in sim.received["b"] if p[1] == 7] == [0]    # delivered once
    stats = rel["a"].stats()
    assert stats["reliability"]["copies"] == 1 and stats["reliability"]["fast_resends"] == 0
    row = stats["ledger"][7]
    assert (row["sent"], row["delivered"], row["in_flight"]) == (2, 2, 0)
    assert rel["b"].stats()["ledger"][7]["duplicates"] == 1


def test_without_loss_measured_no_copy_is_sent():
    sim, rel, carried = duplex()
    reliable_at(sim, 15.0)
    sim.run(40.0)
    assert rel["a"].engine.spare.loss() < COPY_LOSS
    assert sum(ks.count(0) for ks in carried) == 1
    assert rel["a"].stats()["reliability"]["copies"] == 0


def test_under_turns_a_copy_never_keeps_the_leaders_turn():
    from tests.runtime.test_fast_resend import mission_copies, offer_missions, turns_pair
    sim, rel, written = turns_pair(cmd_every=1000.0)        # a quiet surface: missions only
    sim.drop("surface", *range(1, 1 + int(COPY_LOSS * LOSS_WINDOW) + 1))   # loss measured
    offer_missions(sim, 3, every=5.0, start=20.0)
    sim.run(40.0)
    assert rel["surface"].engine.spare.loss() >= COPY_LOSS
    surface = sim.links["surface"].mac
    for k in range(3):
        (t, n), = mission_copies(written, k)                 # one copy: nothing rode with it
        after = [keys for when, number, keys in written["surface"] if number == n + 1]
        assert after == [[]]                     # the next packet: the notice alone, no copy
    assert rel["surface"].stats()["reliability"]["copies"] == 0
    assert surface.counts["grants_sent"] > 10
