"""DESERT crashing at random on purpose (uwgen.emulator.chaos.Crasher, --crash-every)."""
from __future__ import annotations

import time

import pytest

from uwgen.cli import main
from uwgen.emulator import run_emulator
from uwgen.emulator.chaos import Crasher

from .helpers import connect, fast_link, wait_for

pytestmark = pytest.mark.timeout(30)


def test_the_emulator_crashes_at_random_and_comes_back_each_time():
    with run_emulator(fast_link()) as emu:
        client = connect(emu.port("a"))
        with Crasher(emu, every=0.15, down=0.05, seed=2) as crasher:
            assert wait_for(lambda: emu.restarts >= 3, timeout=10.0)
            # The client's connection was cut by the first crash.
            client.settimeout(2.0)
            try:
                assert client.recv(1) == b""
            except ConnectionResetError:
                pass
        assert crasher.crashes == emu.restarts
        settled = emu.restarts
        assert emu.wait_listening(2.0)
        again = connect(emu.port("a"))                       # it listens after the last one
        time.sleep(0.4)
        assert emu.restarts == settled                       # no crash after stop()
        again.close(), client.close()


def test_crash_intervals_are_random_but_repeatable_with_a_seed():
    class FakeEmu:
        def __init__(self):
            self.calls = []

        def restart(self, delay, wait):
            self.calls.append(delay)

    draws = [Crasher(FakeEmu(), every=10.0, seed=7).rng.expovariate(0.1) for _ in range(2)]
    assert draws[0] == draws[1]
    assert Crasher(FakeEmu(), every=10.0, seed=8).rng.expovariate(0.1) != draws[0]


@pytest.mark.parametrize("every, down", [(0.0, 1.0), (-1.0, 1.0), (1.0, -0.5)])
def test_bad_crash_settings_are_refused(every, down):
    with pytest.raises(ValueError):
        Crasher(object(), every=every, down=down)


def test_the_cli_refuses_a_bad_crash_interval(capsys):
    with pytest.raises(SystemExit) as exited:
        main(["emulate", "--ports", "0", "0", "--crash-every", "0"])
    assert exited.value.code == 2
    assert "--crash-every: must be a number in more than 0" in capsys.readouterr().err


def test_the_cli_runs_with_crashes_and_reports_them(capsys):
    assert main(["emulate", "--ports", "0", "0", "--period", "0.02", "--crash-every", "0.2",
                 "--crash-down", "0.05", "--duration", "1.5"]) == 0
    out = capsys.readouterr().out
    assert "node1 127.0.0.1:" in out and "dropped_restart" in out
    crashed = [line for line in out.splitlines() if line.startswith("DESERT crashed")]
    assert crashed and int(crashed[0].split()[2]) >= 1


def test_two_links_survive_repeated_crashes_with_nothing_delivered_twice():
    # Real sockets and the links' own connection threads, DESERT crashing every ~1.2 s.
    from uwgen.emulator import NodeSpec, Scenario
    from uwgen.manifest.model import LinkConfig, LinkPolicy
    from uwgen.runtime.link.link import Link
    from uwgen.runtime.link.scheduler import DROP_REASONS

    period = 0.05
    scen = Scenario(nodes=[NodeSpec("a", dest="b"), NodeSpec("b", position=(30, 0, 0))],
                    period=period, bitrate=48_000.0, seed=3)
    got: list[bytes] = []
    with run_emulator(scen) as emu:
        config = LinkConfig(max_read_length=64, period=period)
        tx = Link(port=emu.port("a"), config=config, name="a", fragment_id=250)
        rx = Link(port=emu.port("b"), config=config, name="b", fragment_id=250,
                  on_payload=got.append)
        tx.add_channel(4, LinkPolicy(queue="fifo", depth=500))
        tx.start(), rx.start()
        try:
            assert wait_for(lambda: tx.connected and rx.connected, 5.0)
            with Crasher(emu, every=1.2, down=0.2, seed=4) as crasher:
                seq, end = 0, time.monotonic() + 7.0
                while time.monotonic() < end:
                    tx.offer(4, bytes([0, 4]) + b"%08d" % seq + b"y" * (seq % 40))
                    seq += 1
                    time.sleep(0.02)
            crashes = crasher.crashes
            last_crash_count = len(got)
            # flowing again (a reconnect backs off, and a loaded machine is slow: wait long)
            assert wait_for(lambda: len(got) > last_crash_count, 20.0)
        finally:
            tx.stop(), rx.stop()
    assert crashes >= 2
    numbers = [int(p[2:10]) for p in got]
    assert numbers == sorted(set(numbers))                  # in order, none twice
    assert all(p == bytes([0, 4]) + b"%08d" % n + b"y" * (n % 40) for p, n in zip(got, numbers))
    stats = tx.stats()
    # Crashes close together can fall inside one outage (backoff + probation): at least one
    # reconnection, at most one per crash.
    assert 1 <= stats["connection"]["reconnects"] <= crashes
    c = stats["channels"][4]
    assert c["offered"] == c["sent"] + c["queued"] + sum(c[r] for r in DROP_REASONS)
