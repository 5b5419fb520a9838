"""One-way latency = tick wait + carrier listen + transmission time + propagation delay."""
from __future__ import annotations

import pytest

from uwgen.emulator import EmulatorCore, NodeSpec, Scenario

from .helpers import two_nodes


def deliver(scen: Scenario, writes: list[tuple[float, bytes]], source: str = "a",
            dest: str = "b"):
    core = EmulatorCore(scen)
    core.client_attached(dest, 0.0)
    for t, data in writes:
        core.client_data(source, t, data)
    return core, core.run_until_idle()


def expected_latency(scen: Scenario, nbytes: int, distance: float, tick_wait: float) -> float:
    return (tick_wait + scen.listen_time + (nbytes + 4) * 8 / scen.bitrate
            + distance / scen.sound_speed)


@pytest.mark.parametrize("distance", [15.0, 300.0, 1500.0, 4000.0])
@pytest.mark.parametrize("nbytes", [1, 30, 64])
def test_latency_is_tick_wait_plus_listen_plus_transmission_plus_propagation(distance, nbytes):
    scen = two_nodes(distance, period=0.2, bitrate=4800.0)
    written = 0.13                       # the next send tick is at 0.2: 0.07 s of tick wait
    _, out = deliver(scen, [(written, bytes(nbytes))])
    assert len(out) == 1
    assert out[0].time - written == pytest.approx(
        expected_latency(scen, nbytes, distance, tick_wait=0.07), abs=1e-9)


def test_tick_wait_is_less_than_one_period_wherever_the_write_falls():
    scen = two_nodes(300.0, period=0.5, bitrate=4800.0)
    base = expected_latency(scen, 10, 300.0, tick_wait=0.0)
    for i in range(20):
        written = 0.013 + i * 0.37        # phases all over the period
        _, out = deliver(scen, [(written, bytes(10))])
        wait = out[0].time - written - base
        assert 0.0 < wait <= 0.5 + 1e-9
        # ... and the packet left exactly on the node's tick grid.
        assert (out[0].sent_at - scen.listen_time) / 0.5 == pytest.approx(
            round((out[0].sent_at - scen.listen_time) / 0.5), abs=1e-9)


@pytest.mark.parametrize("nbytes, distance, measured", [
    (1, 1500.0, 1.03),     # wire-format.md section 1: measured on DESERT 4.0.0 at 4800 bit/s
    (100, 1500.0, 1.19),
    (100, 15.0, 0.20),
])
def test_reproduces_the_latencies_measured_on_real_desert(nbytes, distance, measured):
    # Defaults (carrier listen 0.01 s + up to 0.01 s of jitter), a write just before a tick,
    # and a max_read_length large enough for 100 bytes in one packet as in the measurement.
    scen = Scenario(nodes=[NodeSpec("a", dest="b"), NodeSpec("b", position=(distance, 0, 0))],
                    period=0.2, bitrate=4800.0, max_read_length=128, seed=3)
    latencies = []
    for k in range(20):
        written = 0.195 + 0.2 * k       # 5 ms before tick k + 1
        core = EmulatorCore(scen)
        core.client_attached("b", 0.0)
        core.client_data("a", written, bytes(nbytes))
        (d,) = core.run_until_idle()
        latencies.append(d.time - written)
    assert min(latencies) >= measured - 0.012
    assert max(latencies) <= measured + 0.012
    assert sum(latencies) / len(latencies) == pytest.approx(measured, abs=0.01)


def test_carrier_listen_jitter_stays_within_its_bounds():
    scen = two_nodes(15.0, period=0.2, bitrate=4800.0, listen_jitter=0.01)
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    core.client_data("a", 0.1, bytes(64 * 50))
    out = core.run_until_idle()
    listens = [d.sent_at - round(d.sent_at / 0.2) * 0.2 for d in out]
    assert len(out) == 50
    assert min(listens) >= 0.01 - 1e-9 and max(listens) <= 0.02 + 1e-9
    assert max(listens) - min(listens) > 0.005      # really random, not a constant


def test_202_bytes_with_max_read_length_64_arrive_as_64_64_64_10_one_per_period_in_order():
    scen = two_nodes(300.0, period=0.2, bitrate=4800.0, max_read_length=64)
    data = bytes(i % 251 for i in range(202))
    core, out = deliver(scen, [(0.05, data)])
    assert [len(d.data) for d in out] == [64, 64, 64, 10]
    assert [d.offset for d in out] == [0, 64, 128, 192]
    assert b"".join(d.data for d in out) == data
    sends = [d.sent_at for d in out]
    assert [b - a for a, b in zip(sends, sends[1:])] == pytest.approx([0.2, 0.2, 0.2])
    assert core.counters("a")["packets_queued"] == 4
    assert core.counters("a")["max_queue_bytes"] == 202


def test_each_node_can_have_its_own_period_and_max_read_length():
    scen = Scenario(nodes=[NodeSpec("a", dest="b", period=0.5, max_read_length=10),
                           NodeSpec("b", position=(100, 0, 0))],
                    period=0.2, max_read_length=64, listen_jitter=0.0)
    core, out = deliver(scen, [(0.0, bytes(25))])
    assert [len(d.data) for d in out] == [10, 10, 5]
    sends = [d.sent_at for d in out]
    assert [b - a for a, b in zip(sends, sends[1:])] == pytest.approx([0.5, 0.5])


def test_a_node_phase_shifts_its_ticks():
    scen = Scenario(nodes=[NodeSpec("a", dest="b", phase=0.05), NodeSpec("b", position=(15, 0, 0))],
                    period=0.2, listen_jitter=0.0)
    _, out = deliver(scen, [(0.0, b"x")])
    assert out[0].sent_at == pytest.approx(0.25 + scen.listen_time)
