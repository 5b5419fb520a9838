"""Filling a packet's tail: the message that keeps the best fill, without changing shares."""
from __future__ import annotations

from itertools import combinations

from hypothesis import given
from hypothesis import strategies as st

from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.wire import envelope
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.link.filling import best_fill, first_keeping_best
from uwgen.runtime.link.packets import PACKET_COUNTERS, Packer, message_measure
from uwgen.runtime.link.scheduler import LinkScheduler
from uwgen.runtime.stats import Counters


def brute_best(sizes: list[int], budget: int) -> int:
    return max(sum(c) for r in range(len(sizes) + 1) for c in combinations(sizes, r)
               if sum(c) <= budget)


def payload(key: int, size: int, n: int = 0) -> bytes:
    """A wire format 1 topic payload of `size` bytes on id `key` (below 24)."""
    return bytes((0, key)) + n.to_bytes(4, "big") + bytes(size - 6)


def test_the_tail_takes_the_message_that_fills_it_not_the_next_in_claim_order():
    # Room 19 with 6-, 8-, 11- and 14-byte messages: claim order would take the 6, then the 8
    # (5 bytes left empty); 8 + 11 fill it exactly.
    assert first_keeping_best([6, 8, 11, 14], 19) == 1
    assert best_fill([6, 8, 11, 14], 19) == 19
    assert first_keeping_best([6, 8, 11, 14], 60) == 0      # everything fits: claim order
    assert first_keeping_best([20, 30], 10) is None


@given(st.lists(st.integers(1, 40), min_size=1, max_size=7), st.integers(0, 80))
def test_the_chosen_message_is_the_first_one_in_some_best_fill(sizes, budget):
    i = first_keeping_best(sizes, budget)
    best = brute_best(sizes, budget)
    assert best_fill(sizes, budget) == best
    if i is None:
        assert all(s > budget for s in sizes)
        return
    assert sizes[i] + brute_best(sizes[:i] + sizes[i + 1:], budget - sizes[i]) == best
    for j in range(i):          # no earlier one would have kept the best fill
        assert sizes[j] > budget or sizes[j] + brute_best(sizes[:j] + sizes[j + 1:],
                                                          budget - sizes[j]) < best


def test_the_scheduler_fills_only_when_asked_and_only_at_the_tail():
    clock = ManualClock()
    s = LinkScheduler(clock, measure=message_measure)
    for key, size in ((1, 6), (2, 8), (3, 11), (4, 14)):
        s.add_channel(key, LinkPolicy(queue="fifo", depth=10))
        s.offer(key, payload(key, size))
    assert s.next_payload(0.0, 19)[0] == 1                   # claim order: the 6-byte message
    for key, size in ((1, 6),):
        s.offer(key, payload(key, size))
    assert s.next_payload(0.0, 19, fill=True)[0] == 2        # the 8, so that the 11 fits after it
    assert s.next_payload(0.0, 11, fill=True)[0] == 3


def test_the_message_measure_is_what_the_packer_charges():
    for p in (payload(4, 6), bytes((0, 0x18, 250)) + bytes(20), bytes((2, 20, 7, 0xF5))):
        assert message_measure(p) == envelope.from_v1(p).size(last=False)


def packets(channels: dict[int, tuple[LinkPolicy, int]], count: int) -> list[envelope.Envelope]:
    """`count` packets of a saturated 64-byte link, every channel always full."""
    clock = ManualClock()
    s = LinkScheduler(clock, measure=message_measure)
    for key, (policy, _) in channels.items():
        s.add_channel(key, policy)
    packer = Packer(s, sender=1, max_read_length=64, counters=Counters(PACKET_COUNTERS))
    out = []
    for _ in range(count):
        queued = {key: st["queued"] for key, st in s.stats().items()}
        for key, (_, size) in channels.items():
            for _ in range(10 - queued[key]):
                s.offer(key, payload(key, size) if key < 24 else bytes((0, 0x18, key)) + bytes(size - 3))
        out.append(envelope.decode(packer.next_packet(0.0)))
    return out


def test_saturated_packets_of_small_messages_come_out_nearly_full():
    fifo = LinkPolicy(queue="fifo", depth=100)
    envs = packets({10: (fifo, 6), 11: (fifo, 8), 12: (fifo, 11), 13: (fifo, 14)}, 200)
    sizes = [len(e.encode()) + 1 for e in envs]          # frame byte included: at most 64
    # (a message joining a run costs less than the measure the tail is filled by counts, so a
    # tail may keep a byte or two it could have used)
    assert max(sizes) <= 64 and sum(sizes) / len(sizes) >= 62.0
    counts = [sum(1 for e in envs for m in e.messages if m.id == k) for k in (10, 11, 12, 13)]
    assert max(counts) - min(counts) <= 3                 # equal weights: equal shares (1 %)


def test_filling_keeps_shares_in_proportion_to_priority():
    # One priority-10 topic and 49 priority-0 ones whose messages are 6 or 7 bytes: filling
    # every packet exactly would need 5 six-byte and 4 seven-byte messages and starve the
    # six-byte ones; at the tail only, the top topic keeps its 11/60.
    channels = {1: (LinkPolicy(queue="fifo", depth=100, priority=10), 6)}
    channels.update({k: (LinkPolicy(queue="fifo", depth=100), 6 if k < 24 else 7) for k in range(2, 51)})
    envs = packets(channels, 300)
    ids = [m.id for e in envs for m in e.messages]
    assert 0.17 <= ids.count(1) / len(ids) <= 0.19
    others = [ids.count(k) / len(ids) for k in range(2, 51)]
    assert min(others) >= 0.014 and max(others) <= 0.019


def saturated_counts(top: LinkPolicy, top_size: int, seconds: float = 240.0) -> dict[int, int]:
    """Messages per id of `seconds` of a saturated 64-byte link, one packet per 0.2 s of a
    simulated clock: topic 1 (`top`, `top_size`-byte payloads) and 49 priority-0 topics of
    4-byte bodies (ids 2-31 one byte shorter in the envelope than ids 32-50)."""
    clock = ManualClock()
    s = LinkScheduler(clock, measure=message_measure)
    s.add_channel(1, top)
    for key in range(2, 51):
        s.add_channel(key, LinkPolicy(queue="fifo", depth=20))
    packer = Packer(s, sender=1, max_read_length=64, counters=Counters(PACKET_COUNTERS))
    counts = dict.fromkeys(range(1, 51), 0)
    for step in range(int(seconds / 0.2)):
        now = step * 0.2
        clock.set(now)
        queued = {key: st["queued"] for key, st in s.stats().items()}
        for key in range(1, 51):
            for _ in range(5 - queued[key]):
                body = bytes(top_size - 2) if key == 1 else bytes(4)
                s.offer(key, (bytes((0, key)) if key < 24 else bytes((0, 0x18, key))) + body)
        for m in envelope.decode(packer.next_packet(now)).messages:
            counts[m.id] += 1
    return counts


def test_no_topic_starves_behind_a_strict_topic_that_leaves_room_for_one_message():
    # The strict topic's 50-byte message leaves 7 bytes: one message of an id from 32 fills
    # them exactly, one of ids 2-31 leaves a byte. The best fit alone would serve only ids
    # from 32; a channel passed over at a packet's tail is served before the next pass.
    counts = saturated_counts(LinkPolicy(queue="fifo", depth=20, priority=10, strict=True), 50)
    assert counts[1] == 1200
    assert min(counts[k] for k in range(2, 51)) > 0, counts
    short, long = [counts[k] for k in range(2, 32)], [counts[k] for k in range(32, 51)]
    assert min(short) >= max(long) - 2          # shares stay equal, whatever the id's length


def test_no_topic_starves_in_a_saturated_run_without_a_strict_topic():
    counts = saturated_counts(LinkPolicy(queue="fifo", depth=20, priority=10), 6)
    assert min(counts.values()) > 0, counts
    others = [counts[k] for k in range(2, 51)]
    assert max(others) - min(others) <= 2
