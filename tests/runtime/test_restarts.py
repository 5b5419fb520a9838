"""Restarts seen on every wire-format-2 link (docs/seams.md section 8): a sender that starts
again picks a new epoch, carried in K whether the link is sealed or not, so its packets and
reliable messages are never taken as repeats of its previous start's; the sender's ledger
closes across a far restart, what cannot be known counted `unknown`."""
from __future__ import annotations

import itertools
import logging

import pytest

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.duplex import DuplexSim
from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.delivery.reliability import Reliability
from uwgen.runtime.link.hooks import join_hooks
from uwgen.security.packet_seal import PacketSeal

from runtime.test_reliability_link import BEST_EFFORT, RELIABLE, Wall, closes
from security.helpers import KEY, config

PERIOD = 0.5


def restartable(sealed: bool, per: float = 0.0, offsets: dict | None = None,
                max_ages: dict | None = None, clock_exchange: bool = False):
    """Two sides a (sender 1) and b (sender 2); a's reliable topic 7. Unsealed, each side's
    reliability gives K (a fresh epoch per start); sealed, the seal does, and reads T with the
    offsets reliability measures, as the bridge wires them. `max_ages`: ids judged for age."""
    scen = Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                           NodeSpec("b", position=(300, 0, 0), dest="a")],
                    period=PERIOD, max_read_length=64, per=per, seed=3, bitrate=4800.0)
    clock = ManualClock()
    engines: dict[str, Reliability] = {}
    epochs = (bytes([n]) * 6 for n in itertools.count(1))

    def hooks_for(side: str):
        me, peer = (1, 2) if side == "a" else (2, 1)
        wall = Wall(clock, (offsets or {}).get(side, 0.0))
        seal = None
        if sealed:
            seal = PacketSeal(KEY, config(me, peer, "b" if side == "a" else "a",
                                          modes={7: "sign", 4: "sign", 9: "sign"}),
                              wall=wall, clock=clock, name=side,
                              epoch_source=lambda: next(epochs))
        engines[side] = Reliability(me, period=PERIOD, reliable={7: 60.0}, max_ages=dict(max_ages or {}),
                                    wall=wall, name=side, max_read_length=64,
                                    other_overhead=0 if seal is None else seal.hooks().overhead,
                                    epoch_source=None if sealed else (lambda: next(epochs)),
                                    clock_exchange=clock_exchange)
        if seal is not None:
            seal.use_offsets(engines[side].offsets.of)
        return join_hooks(engines[side].hooks(), seal.hooks() if seal is not None else None)
    sim = DuplexSim(scen, ("a", "b"), hooks_for=hooks_for, wire_format=2, clock=clock)
    return sim, engines


def send(sim: DuplexSim, start: float, marker: int, count: int) -> None:
    """a offers `count` reliable messages (marker, i), one a period, from `start`."""
    for i in range(count):
        sim.at(start + i * PERIOD, lambda i=i: sim.links["a"].offer(7, bytes((0, 7, marker, i)) + bytes(6)))


def got(sim: DuplexSim, marker: int) -> list[int]:
    return sorted(p[3] for _, p in sim.received["b"] if p[1] == 7 and p[2] == marker)


@pytest.mark.parametrize("sealed", [False, True], ids=["unsealed", "sealed"])
@pytest.mark.parametrize("after", [5, 20, 200])
def test_a_restarted_sender_loses_no_reliable_message(sealed, after, caplog):
    sim, rel = restartable(sealed)
    sim.links["a"].add_channel(7, RELIABLE)
    sim.links["b"].add_channel(4, BEST_EFFORT)
    for i in range(int(after * PERIOD * 1.5) + 80):
        sim.at(i + 0.25, lambda i=i: sim.links["b"].offer(4, bytes((0, 4, i % 256))))
    send(sim, 0.0, 1, after)
    end = after * PERIOD + 5.0
    sim.run(end)
    assert got(sim, 1) == list(range(after))
    sim.restart("a").add_channel(7, RELIABLE)        # a new process: numbers from 0 again
    send(sim, end + 1, 2, 30)
    with caplog.at_level(logging.INFO, logger="uwgen.link.reliability"):
        sim.run(end + 1 + 30 * PERIOD + 20)
    assert got(sim, 2) == list(range(30))            # none taken for a repeat
    assert rel["b"].counters["restarts_seen"] == 1 and "sender 1 started again" in caplog.text
    row = rel["a"].ledger()[7]
    assert row["delivered"] == 30 and closes(row)


@pytest.mark.parametrize("sealed", [False, True], ids=["unsealed", "sealed"])
def test_a_far_restart_leaves_the_senders_ledger_exact_with_what_cannot_be_known_unknown(sealed):
    sim, rel = restartable(sealed)
    a = sim.links["a"]
    a.add_channel(7, RELIABLE)
    sim.links["b"].add_channel(4, BEST_EFFORT)
    send(sim, 0.0, 1, 60)
    sim.run(10.0)                                   # mid-stream: some of a's packets unreported
    b = sim.restart("b")
    b.add_channel(4, BEST_EFFORT)
    for i in range(60):
        sim.at(10.25 + i, lambda i=i: sim.links["b"].offer(4, bytes((0, 4, i))))
    sim.run(80.0)
    row = rel["a"].ledger()[7]
    assert closes(row) and row["in_flight"] == 0
    assert row["lost_on_link"] == 0                  # no loss on this channel: none is called lost
    assert set(got(sim, 1)) == set(range(60))        # the new start got the rest


@pytest.mark.parametrize("farewell", [False, True], ids=["cut", "farewell"])
def test_a_clean_stop_sends_the_last_acknowledgements_so_the_peers_ledger_closes(farewell):
    sim, rel = restartable(sealed=False)
    a = sim.links["a"]
    a.add_channel(4, BEST_EFFORT)
    for i in range(20):
        sim.at(i * PERIOD, lambda i=i: a.offer(4, bytes((0, 4, i)) + bytes(4)))
    sim.run(20 * PERIOD + 2.0)                       # all of them arrived
    if farewell:
        assert rel["b"].farewell()
        sim.run(sim.clock.now() + 2 * PERIOD + 1.0)
        assert not rel["b"].farewell_pending
    sim.drop("b", *range(sim.written["b"], sim.written["b"] + 1000))    # b has stopped
    sim.run(sim.clock.now() + 30.0)
    row = rel["a"].ledger()[4]
    assert closes(row) and row["sent"] == 20
    assert (row["in_flight"] == 0 and row["delivered"] == 20) if farewell else row["in_flight"] > 0
