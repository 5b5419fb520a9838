"""Reconnecting to a restarted DESERT quickly, "connected" only once proven, and an unserved port.

DESERT drops every byte that arrives for a node with no client, so the reconnect backoff is
capped at max(one period, 1 s); a connection counts as connected only once it has proved itself;
a second client on a port that already has one is warned about (DESERT serves one per port).
"""
from __future__ import annotations

import logging
import time

import pytest

from uwgen.emulator import NodeSpec, Scenario, run_emulator
from uwgen.manifest.model import LinkConfig, LinkPolicy
from uwgen.runtime.link.link import Link
from uwgen.runtime.link.probation import reconnect_cap

from emulator.helpers import wait_for

pytestmark = pytest.mark.timeout(60)

PERIOD = 0.2
KEY = 7


def scenario() -> Scenario:
    return Scenario(nodes=[NodeSpec("surface", position=(0, 0, 0), dest="vehicle"),
                           NodeSpec("vehicle", position=(150, 0, 0), dest="surface")],
                    period=PERIOD, max_read_length=64, bitrate=48_000.0, seed=5)


def link(port: int, name: str, **kw) -> Link:
    # The default backoff (what a bridge gets): capped at max(period, 1 s).
    lk = Link(host="127.0.0.1", port=port, config=LinkConfig(max_read_length=64, period=PERIOD),
              name=name, **kw)
    lk.add_channel(KEY, LinkPolicy(queue="fifo", depth=100))
    return lk


def test_reconnects_within_one_backoff_cap_after_a_long_desert_restart():
    cap = reconnect_cap(PERIOD)
    assert cap == 1.0
    with run_emulator(scenario()) as emu:
        lk = link(emu.port("surface"), "surface")
        lk.start()
        try:
            assert wait_for(lambda: lk.connected, 5)
            # Down for 4 s: an uncapped exponential backoff (0.1 s doubling) would by then wait
            # 1.6 s, then 3.2 s, between attempts.
            emu.restart(delay=4.0, wait=False)
            assert wait_for(lambda: not lk.connected, 2)
            assert emu.wait_listening(10)
            back = time.monotonic()
            assert wait_for(lambda: lk.connected, 5)
            took = time.monotonic() - back
            stats = lk.stats()["connection"]
        finally:
            lk.stop()
    # One capped delay, the 0.3 s probation, and scheduling slack on a busy machine.
    assert took <= cap + lk.connection.proof.probation + 0.4
    assert stats["reconnects"] == 1 and stats["connects"] == 2


def test_connected_is_not_reported_before_the_probation_and_a_restart_is_counted_once():
    with run_emulator(scenario()) as emu:
        lk = link(emu.port("surface"), "surface")
        lk.start()
        try:
            assert wait_for(lambda: lk.connection._sock is not None, 5)
            assert not lk.connected                      # TCP is up, but not proven yet
            assert wait_for(lambda: lk.connected, 2)
            assert lk.stats()["connection"]["connects"] == 1
        finally:
            lk.stop()


def test_a_second_client_on_a_busy_port_is_warned_about_once(caplog):
    with run_emulator(scenario()) as emu:
        first = link(emu.port("surface"), "first")
        second = link(emu.port("surface"), "second")
        second.connection.proof.unserved_after = 1.5
        peer = link(emu.port("vehicle"), "peer")
        first.start()
        assert wait_for(lambda: first.connected, 5)
        second.start(), peer.start()
        try:
            with caplog.at_level(logging.WARNING, logger="uwgen.link"):
                assert wait_for(lambda: second.connected and peer.connected, 5)
                end = time.monotonic() + 3.5
                while time.monotonic() < end:            # the far side talks: first hears it
                    peer.offer(KEY, b"\x00\x07hello")
                    second.offer(KEY, b"\x00\x07lost?")
                    time.sleep(0.2)
            first_rx = first.stats()["connection"]["frames_received"]
            s2 = second.stats()["connection"]
        finally:
            first.stop(), second.stop(), peer.stop()
    warnings = [r.getMessage() for r in caplog.records if "serves one client per port" in r.getMessage()]
    assert first_rx > 0 and s2["frames_received"] == 0
    assert s2["unserved_warnings"] == 1 and len(warnings) == 1
    assert "[second]" in warnings[0] and "Stop the other client" in warnings[0]
