"""The age bound whatever the clocks and delays (docs/wire-format.md section 15.5, docs/seams.md
section 8): each side measures its peer's clock offset from an exchange, a held packet is
refused however long it was held, and a clock beyond the tolerance is named with its figure."""
from __future__ import annotations

import logging
import re

import pytest

from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.delivery.clock_offset import ClockOffsets, sample
from uwgen.runtime.delivery.freshness import stamp

from runtime.test_reliability_link import BEST_EFFORT, duplex, numbers

COMMAND = LinkPolicy(queue="fifo", depth=8)


def commands(sim, every: float = 2.0, count: int = 10, start: float = 0.0):
    """a sends a command (id 9, max age 2 s) every `every` s; b answers with best-effort topic
    4 every second, so each side's packets are reported by the other (an exchange)."""
    a, b = sim.links["a"], sim.links["b"]
    a.add_channel(9, COMMAND)
    b.add_channel(4, BEST_EFFORT)
    for i in range(count):
        sim.at(start + i * every, lambda i=i: a.offer(9, bytes((2, 9, i, 0xF5))))
    for i in range(int(start + count * every) + 1):
        sim.at(i + 0.5, lambda i=i: b.offer(4, bytes((0, 4, i % 256))))
    return a, b


def test_the_offset_is_exact_for_symmetric_transits_and_bounded_otherwise():
    # peer 7 s ahead, 0.4 s each way, held 1 s: offset 7 exactly; error covers any split
    off, delay, error = sample(100.0, 1.0, 100.0 + 0.4 + 7 + 1.0, 100.0 + 0.4 + 1.0 + 0.4)
    assert abs(off - 7.0) < 1e-9 and abs(delay - 0.8) < 1e-9 and error >= 0.4
    # the same exchange with all of the delay one way: the truth is still within the error
    off, _, error = sample(100.0, 1.0, 100.0 + 0.0 + 7 + 1.0, 100.0 + 1.0 + 0.8)
    assert abs(off - 7.0) <= error


def test_a_held_report_loses_the_clock_filter_to_a_prompt_one():
    offsets = ClockOffsets()
    wall = 1_700_000_000.0
    offsets.built(1, wall)
    offsets.built(2, wall + 1)
    prompt = offsets.reported(5, 1, 0, stamp(wall + 0.5), wall + 1.0)
    held = offsets.reported(5, 2, 0, stamp(wall + 1.5), wall + 45.0)   # its report held 43 s
    assert held.offset == prompt.offset and abs(prompt.offset) < 0.2
    assert offsets.reported(5, 3, 0, stamp(wall), wall) is None        # a packet never built
    assert offsets.reported(5, 1, 15, stamp(wall), wall + 2) is None  # a saturated hold


@pytest.mark.parametrize("hold", [10.0, 44.0, 64.0, 130.0])
def test_a_command_held_on_the_way_is_never_delivered_after_its_max_age(hold, caplog):
    sim, rel = duplex(max_ages={7: 30.0, 9: 2.0})
    a, _ = commands(sim, count=20)
    sim.run(8.0)                                    # exchanges: b knows a's offset
    before = sorted(numbers(sim, "b", 9))
    sim.hold("a", hold, sim.written["a"], sim.written["a"] + 1)
    with caplog.at_level(logging.WARNING, logger="uwgen.link.reliability"):
        sim.run(40.0 + hold + 10)
    # command i is published at 2 i s: none is delivered after its max age, 2 s
    late = [(p[2], t) for t, p in sim.received["b"] if p[1] == 9 and t - 2 * p[2] > 2.0]
    assert late == []
    assert rel["b"].counters["stale"] >= 1 and "old (age item" in caplog.text
    assert rel["b"].offsets.of(1) is not None


def test_a_held_command_before_any_exchange_is_refused_as_unexplained(caplog):
    sim, rel = duplex(max_ages={7: 30.0, 9: 2.0})
    a = sim.links["a"]
    a.add_channel(9, COMMAND)
    sim.hold("a", 44.0, 0)
    sim.at(0.0, lambda: a.offer(9, bytes((2, 9, 1, 0xF5))))
    with caplog.at_level(logging.WARNING, logger="uwgen.link.reliability"):
        sim.run(50.0)
    assert numbers(sim, "b", 9) == []
    assert rel["b"].counters["unexplained_delay"] == 1
    assert "took 44." in caplog.text and "sender 1" in caplog.text


@pytest.mark.parametrize("offset", [3.0, -3.0])
def test_commands_work_with_clocks_within_the_tolerance(offset):
    sim, rel = duplex(max_ages={7: 30.0, 9: 2.0}, offsets={"b": offset})
    commands(sim)
    sim.run(25.0)
    assert sorted(numbers(sim, "b", 9)) == list(range(10))
    measured = rel["b"].offsets.of(1)
    assert abs(measured.offset + offset) <= measured.error      # b measures a's clock: -offset
    assert rel["b"].stats()["reliability"]["clock_offsets"][1]["samples"] >= 1


@pytest.mark.parametrize("offset", [6.0, -6.0, 30.0, -30.0])
def test_commands_beyond_the_tolerance_are_refused_and_the_offset_named(offset, caplog):
    """Before the first exchange a command is judged with the clocks taken within the tolerance
    (an apparent transit of 6 s passes when the command is fresh); from the first exchange on,
    every one is refused `clock_offset`."""
    sim, rel = duplex(max_ages={7: 30.0, 9: 2.0}, offsets={"b": offset})
    with caplog.at_level(logging.WARNING, logger="uwgen.link.reliability"):
        commands(sim)
        sim.run(25.0)
    measured_at = rel["b"].first_offset_at[1]
    assert measured_at < 4.0                                  # within the first exchange
    assert [t for t, p in sim.received["b"] if p[1] == 9 and t > measured_at] == []
    assert len(numbers(sim, "b", 9)) <= (0 if abs(offset) > 15 else 2)
    c = rel["b"].counters
    assert c["clock_offset"] >= 8
    measured = rel["b"].offsets.of(1)
    assert abs(-offset - measured.offset) <= measured.error
    side = "ahead of" if offset < 0 else "behind"
    told = re.search(r"sender 1's clock is ([\d.]+) s (ahead of|behind) ours \(\+-([\d.]+) s", caplog.text)
    assert told.group(2) == side and abs(float(told.group(1)) - abs(offset)) <= float(told.group(3)) + 0.1
    assert "GPS or NTP" in caplog.text and caplog.text.count("[b] sender 1's clock is") == 1


@pytest.mark.parametrize("offset", [-6.0, -30.0])
def test_a_sealed_link_refusing_a_far_clock_names_the_figure(offset, caplog):
    """The seal refuses packets whose time is ahead of the receiver's clock by more than the
    tolerance (nothing of that sender is taken, commands included); its log names by how
    much, once per sender. (A clock behind is refused only past the packet's max age.)"""
    from runtime.test_restarts import restartable
    sim, _ = restartable(sealed=True, offsets={"b": offset})
    sim.links["a"].add_channel(4, BEST_EFFORT)
    for i in range(5):
        sim.at(i * 1.0, lambda i=i: sim.links["a"].offer(4, bytes((0, 4, i))))
    with caplog.at_level(logging.ERROR, logger="uwgen.security"):
        sim.run(10.0)
    told = re.findall(r"\[b\] sender 1 \(a\): a packet stamped ([\d.]+) s (behind|ahead of) our clock",
                      caplog.text)
    assert len(told) == 1 and abs(float(told[0][0]) - abs(offset)) < 1.0
    assert told[0][1] == ("behind" if offset > 0 else "ahead of") and "GPS or NTP" in caplog.text
