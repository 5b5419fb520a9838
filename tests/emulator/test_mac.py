"""Medium access: ALOHA collisions, TDMA slots, and DESERT's unbounded send queue."""
from __future__ import annotations

from dataclasses import replace

import pytest

from uwgen.emulator import EmulatorCore, NodeSpec, Scenario, TdmaSpec, load_scenario

from .helpers import SCENARIOS, two_nodes


def bursts(scen: Scenario, packets: int, size: int, both: bool = True) -> EmulatorCore:
    """`packets` writes of `size` bytes at the same moment on a (and on b if `both`)."""
    core = EmulatorCore(scen)
    core.client_attached("a", 0.0)
    core.client_attached("b", 0.0)
    for _ in range(packets):
        core.client_data("a", 0.05, b"A" * size)
        if both:
            core.client_data("b", 0.05, b"B" * size)
    core.run_until_idle()
    return core


def collision_ratio(core: EmulatorCore) -> float:
    a, b = core.counters("a"), core.counters("b")
    return (a["lost_collision"] + b["lost_collision"]) / (a["packets_sent"] + b["packets_sent"])


def test_simultaneous_bursts_collide_about_as_measured_on_desert():
    # wire-format.md section 1: both nodes sending bursts at the same moment lost ~30 % of
    # the packets to collisions; one-way traffic at the same settings lost nothing.
    ratios = []
    for seed in range(1, 9):
        scen = two_nodes(1500.0, period=0.5, bitrate=4800.0, listen_jitter=0.01, seed=seed)
        ratios.append(collision_ratio(bursts(scen, packets=20, size=64)))
    mean = sum(ratios) / len(ratios)
    assert 0.15 <= mean <= 0.45, ratios
    one_way = bursts(two_nodes(1500.0, period=0.5, bitrate=4800.0, listen_jitter=0.01),
                     packets=20, size=64, both=False)
    assert one_way.counters("b")["packets_delivered"] == 20
    assert collision_ratio(one_way) == 0.0


def test_half_duplex_nodes_sending_in_lockstep_lose_everything_at_short_range():
    scen = two_nodes(15.0, period=0.2, bitrate=4800.0, listen_jitter=0.0)
    core = bursts(scen, packets=10, size=64)
    assert core.counters("a")["lost_collision"] == core.counters("b")["lost_collision"] == 10


def test_carrier_sense_defers_instead_of_colliding_when_the_other_is_heard():
    # b's ticks come 0.1 s after a's: a's packet (0.113 s on the air) is already arriving
    # when b wants to send, so b waits for silence and nothing collides.
    scen = Scenario(nodes=[NodeSpec("a", dest="b"), NodeSpec("b", position=(15, 0, 0), phase=0.1)],
                    period=0.4, bitrate=4800.0, listen_jitter=0.0)
    core = bursts(scen, packets=10, size=64)
    assert collision_ratio(core) == 0.0
    assert core.counters("a")["packets_delivered"] == core.counters("b")["packets_delivered"] == 10


def test_an_overheard_packet_jams_a_third_node():
    # c sends to b while a sends to b: b can hold only one reception at a time.
    scen = Scenario(nodes=[NodeSpec("a", dest="b"), NodeSpec("b", position=(300, 0, 0), dest="a"),
                           NodeSpec("c", position=(600, 0, 0), dest="b")],
                    period=0.5, bitrate=4800.0, listen_jitter=0.0)
    core = EmulatorCore(scen)
    for n in ("a", "b", "c"):
        core.client_attached(n, 0.0)
    core.client_data("a", 0.05, bytes(64))
    core.client_data("c", 0.05, bytes(64))
    core.run_until_idle()
    assert core.counters("b")["lost_collision"] == 2


def test_aloha_collides_where_tdma_does_not():
    tdma_scen = load_scenario(SCENARIOS / "tdma.yaml")     # the core never binds its ports
    aloha_scen = replace(tdma_scen, tdma=None)

    def run(scen):
        core = EmulatorCore(scen)
        for n in ("surface", "vehicle"):
            core.client_attached(n, 0.0)
        for _ in range(30):
            core.client_data("surface", 0.05, bytes(64))
            core.client_data("vehicle", 0.05, bytes(64))
        return core, core.run_until_idle()

    aloha, _ = run(aloha_scen)
    lost = sum(aloha.counters(n)["lost_collision"] for n in ("surface", "vehicle"))
    assert lost >= 10
    tdma, out = run(tdma_scen)
    assert sum(tdma.counters(n)["lost_collision"] for n in ("surface", "vehicle")) == 0
    assert len(out) == 60
    # Every transmission started inside its node's ON window (slot minus guard), as DESERT's
    # UW/TDMA starts them; the guard covers what runs past it.
    frame, guard, slot_len = 1.0, 0.3, 0.5
    for d in out:
        slot = 0 if d.source == "surface" else 1
        into_frame = d.sent_at % frame
        assert slot * slot_len - 1e-9 <= into_frame < (slot + 1) * slot_len - guard


def test_tdma_sends_back_to_back_inside_the_slot():
    scen = Scenario(nodes=[NodeSpec("a", dest="b"), NodeSpec("b", position=(15, 0, 0))],
                    period=0.01, bitrate=9600.0, tdma=TdmaSpec(frame=2.0, guard=0.1))
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    core.client_data("a", 0.0, bytes(64 * 8))
    out = core.run_until_idle()
    duration = (64 + 4) * 8 / 9600
    starts = [d.sent_at for d in out]
    # Slot 0 is [0, 1) with 0.9 s usable: 15 packets would fit; 8 go out one after another.
    assert len(out) == 8 and max(starts) < 0.9
    gaps = [b - a for a, b in zip(starts, starts[1:])]
    assert min(gaps) >= duration - 1e-9


def test_weighted_tdma_slots_start_after_the_slots_before_and_last_their_share():
    # DESERT's manual mode: a 3 s frame, weights 2 and 1: a's slot [0, 2) (ON 1.9 s), b's
    # [2, 3) (ON 0.9 s); a fills its longer window, b starts only inside its own.
    scen = Scenario(nodes=[NodeSpec("a", dest="b"), NodeSpec("b", position=(15, 0, 0), dest="a")],
                    period=0.01, bitrate=9600.0, tdma=TdmaSpec(frame=3.0, guard=0.1, weights=(2, 1)))
    core = EmulatorCore(scen)
    core.client_attached("a", 0.0)
    core.client_attached("b", 0.0)
    core.client_data("a", 0.0, bytes(64 * 40))
    core.client_data("b", 0.0, bytes(64 * 40))
    out = core.run_until_idle()
    duration = (64 + 4) * 8 / 9600
    by = {n: [d.sent_at % 3.0 for d in out if d.source == n and d.sent_at < 3.0] for n in "ab"}
    # a packet takes 0.0567 s: a starts 34 in its 1.9 s window (the first at its period tick),
    # b 16 in its 0.9 s one
    assert duration == pytest.approx(0.05667, abs=1e-4)
    assert len(by["a"]) == 34 and max(by["a"]) < 1.9
    assert len(by["b"]) == 16 and 2.0 - 1e-9 <= min(by["b"]) and max(by["b"]) < 2.9
    assert core.counters("a")["lost_collision"] == core.counters("b")["lost_collision"] == 0


@pytest.mark.parametrize("weights", [(1,), (2, 0), (1, True)], ids=["count", "zero", "bool"])
def test_tdma_weights_that_do_not_name_every_slot_positively_are_refused(weights):
    with pytest.raises(ValueError, match="tdma.weights"):
        two_nodes(100.0, bitrate=4800.0, tdma=TdmaSpec(frame=2.0, guard=0.1, weights=weights))


def test_tdma_guard_that_leaves_no_on_window_is_refused():
    with pytest.raises(ValueError, match="no ON window"):
        two_nodes(100.0, bitrate=4800.0, tdma=TdmaSpec(frame=0.2, guard=0.1))


def test_tdma_packet_starts_anywhere_in_the_window_and_ends_past_it():
    # As DESERT's UW/TDMA: ON is 0.1 - 0.05 = 0.05 s, shorter than a 64-byte packet
    # (0.113 s at 4800 bit/s); one packet starts in each window and runs into the guard.
    scen = two_nodes(100.0, bitrate=4800.0, period=0.01,
                     tdma=TdmaSpec(frame=0.2, guard=0.05, max_packet_per_slot=5))
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    core.client_data("a", 0.0, bytes(64 * 3))
    out = core.run_until_idle()
    assert [round(d.sent_at % 0.2, 6) for d in out] == [0.01, 0.0, 0.0]
    assert len(out) == 3


def test_tdma_starts_at_most_max_packet_per_slot_in_a_window():
    scen = Scenario(nodes=[NodeSpec("a", dest="b"), NodeSpec("b", position=(15, 0, 0))],
                    period=0.01, bitrate=9600.0,
                    tdma=TdmaSpec(frame=2.0, guard=0.1, max_packet_per_slot=3))
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    core.client_data("a", 0.0, bytes(64 * 7))
    out = core.run_until_idle()
    frames = [int(d.sent_at // 2.0) for d in out]
    assert frames == [0, 0, 0, 1, 1, 1, 2]


def test_tdma_full_mac_queue_drops_the_new_packet_and_counts_it():
    # DESERT's queue_size_ (drop_old_ 0): a 2-packet queue in front of a 1-packet slot.
    scen = Scenario(nodes=[NodeSpec("a", dest="b"), NodeSpec("b", position=(15, 0, 0))],
                    period=0.01, bitrate=9600.0,
                    tdma=TdmaSpec(frame=2.0, guard=0.1, max_packet_per_slot=1, queue_size=2))
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    core.client_data("a", 0.0, bytes([1]) * 64 + bytes([2]) * 64 + bytes([3]) * 64 + bytes([4]) * 64)
    out = core.run_until_idle()
    c = core.counters("a")
    assert c["dropped_queue_full"] == 1 and c["max_mac_queue"] == 2
    assert [d.data[0] for d in out] == [1, 2, 3]


def test_send_queue_is_unbounded_and_grows_under_a_fast_writer():
    # Ten times what the link carries (64 B per 0.2 s): nothing is refused, the queue grows.
    scen = two_nodes(300.0, period=0.2, bitrate=4800.0)
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    t, sizes = 0.0, []
    while t < 20.0:
        core.client_data("a", t, bytes(64))
        core.advance(t)
        sizes.append(core.counters("a")["queue_bytes"])
        t += 0.02
    assert sizes[-1] > 10 * 64 * 9 * 0.9                     # ~90 % of 20 s worth waits
    assert all(b >= a - 64 for a, b in zip(sizes, sizes[1:]))  # and it only grows
    assert core.counters("a")["max_queue_bytes"] == max(sizes)
    core.run_until_idle()
    assert core.counters("b")["packets_delivered"] == len(sizes)   # all delivered, late


def test_a_writer_paced_to_the_link_keeps_the_queue_within_one_period_of_data():
    scen = two_nodes(300.0, period=0.2, bitrate=4800.0)
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    for k in range(100):
        core.client_data("a", 0.03 + 0.2 * k, bytes(64))    # 64 bytes per period
    core.run_until_idle()
    assert core.counters("a")["max_queue_bytes"] <= 64
    assert core.counters("b")["packets_delivered"] == 100


def test_a_slow_modem_backs_up_into_the_mac_queue_and_counts_it():
    # 64-byte packets take 0.113 s at 4800 bit/s but the period is 0.05 s: the MAC cannot
    # keep up, and the bytes waiting for it still count as waiting inside the node.
    scen = two_nodes(30.0, period=0.05, bitrate=4800.0)
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    core.client_data("a", 0.0, bytes(64 * 20))
    core.advance(1.0)
    c = core.counters("a")
    assert c["packets_sent"] < 10
    assert c["queue_bytes"] == 64 * (20 - c["packets_sent"])
    core.run_until_idle()
    assert core.counters("b")["packets_delivered"] == 20


@pytest.mark.parametrize("distance", [15.0, 123.456, 777.7, 1499.99, 2345.678])
@pytest.mark.parametrize("bitrate", [4800.0, 9600.0, 1234.5])
def test_back_to_back_packets_of_one_sender_never_collide_by_rounding(distance, bitrate):
    """A packet sent the instant the previous one ends must not overlap it at the receiver
    (arrival ends and starts were once computed by sums that rounded differently)."""
    scen = Scenario(nodes=[NodeSpec("a", dest="b"), NodeSpec("b", position=(distance, 0, 0))],
                    period=0.001, bitrate=bitrate, tdma=TdmaSpec(frame=200.0, guard=0.1))
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    core.client_data("a", 0.0, bytes(64 * 200))
    out = core.run_until_idle()
    assert core.counters("b")["lost_collision"] == 0
    assert len(out) == 200
