"""Packet losses: fixed error rate, missing client, repeatability with a seed."""
from __future__ import annotations

import pytest

from uwgen.emulator import EmulatorCore

from .helpers import two_nodes


def one_way(scen, packets: int, payload: int = 20, attach_at: float | None = 0.0):
    core = EmulatorCore(scen)
    if attach_at is not None:
        core.client_attached("b", attach_at)
    core.client_data("a", 0.0, bytes(payload * packets))
    return core, core.run_until_idle()


@pytest.mark.parametrize("per", [0.05, 0.2, 0.5])
def test_fixed_packet_error_rate_loses_that_fraction(per):
    scen = two_nodes(500.0, period=0.05, bitrate=48000.0, max_read_length=20, per=per, seed=7)
    core, out = one_way(scen, packets=3000)
    b = core.counters("b")
    assert b["lost_per"] + b["packets_delivered"] == 3000
    assert b["lost_per"] / 3000 == pytest.approx(per, abs=0.03)
    assert len(out) == b["packets_delivered"]
    assert b["lost_collision"] == b["lost_snr"] == b["lost_no_client"] == 0


def test_no_loss_without_error_rate_or_snr_model():
    scen = two_nodes(1500.0, period=0.05, bitrate=48000.0, max_read_length=20)
    core, out = one_way(scen, packets=500)
    assert core.counters("b")["packets_delivered"] == 500
    assert b"".join(d.data for d in out) == bytes(20 * 500)


def test_same_seed_same_losses_and_another_seed_other_losses():
    def lost_positions(seed):
        scen = two_nodes(500.0, period=0.05, bitrate=48000.0, max_read_length=4, per=0.3,
                         seed=seed, listen_jitter=0.01)
        core = EmulatorCore(scen)
        core.client_attached("b", 0.0)
        core.client_data("a", 0.0, b"".join(i.to_bytes(4, "big") for i in range(400)))
        got = {int.from_bytes(d.data, "big") for d in core.run_until_idle()}
        return sorted(set(range(400)) - got), core.counters("b")

    first, counters1 = lost_positions(11)
    again, counters2 = lost_positions(11)
    other, _ = lost_positions(12)
    assert first == again and counters1 == counters2
    assert first != other
    assert 60 < len(first) < 180


def test_packets_for_a_node_without_client_are_dropped_and_counted():
    scen = two_nodes(300.0, period=0.1, bitrate=4800.0, max_read_length=10)
    core, out = one_way(scen, packets=5, payload=10, attach_at=None)
    assert out == []
    b = core.counters("b")
    assert b["lost_no_client"] == 5 and b["packets_delivered"] == 0


def test_a_client_that_connects_later_receives_only_new_data():
    scen = two_nodes(300.0, period=0.1, bitrate=4800.0, max_read_length=10)
    core = EmulatorCore(scen)
    core.client_data("a", 0.0, b"old-------" * 3)
    assert core.advance(2.0) == []                      # all three arrived to nobody
    core.client_attached("b", 2.0)
    core.client_data("a", 2.0, b"new-------")
    out = core.run_until_idle()
    assert [d.data for d in out] == [b"new-------"]
    assert core.counters("b")["lost_no_client"] == 3


def test_a_client_that_leaves_stops_receiving_and_the_rest_is_dropped():
    scen = two_nodes(15.0, period=0.1, bitrate=4800.0, max_read_length=10)
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    core.client_data("a", 0.0, bytes(10 * 6))
    first = core.advance(0.35)                           # ticks at 0.1, 0.2, 0.3
    core.client_detached("b", 0.35)
    rest = core.run_until_idle()
    assert len(first) == 3 and rest == []
    assert core.counters("b")["lost_no_client"] == 3


def test_restart_drops_queued_and_in_flight_packets_and_forgets_clients():
    scen = two_nodes(1500.0, period=0.1, bitrate=4800.0, max_read_length=10)
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    core.client_data("a", 0.0, bytes(10 * 10))
    delivered = core.advance(1.25)          # sent at ~0.11, 0.21, ...; 1 s on the way
    core.reset(1.25)
    a = core.counters("a")
    assert a["dropped_restart"] + len(delivered) == 10
    assert a["queue_bytes"] == 0
    assert core.counters("b")["client_connected"] == 0
    assert core.run_until_idle() == []
    assert core.restarts == 1
    # After the restart the node works again, with ticks counted from the restart.
    core.client_attached("b", 2.0)
    core.client_data("a", 2.0, b"after")
    (d,) = core.run_until_idle()
    assert d.data == b"after"
    assert d.sent_at == pytest.approx(2.05 + scen.listen_time, abs=1e-9)   # grid 1.25 + k * 0.1
