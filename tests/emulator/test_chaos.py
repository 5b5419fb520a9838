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
    assert main(["emulate", "--ports", "0", "0", "--crash-every", "0"]) == 2
    assert "--crash-every must be > 0" in capsys.readouterr().err


def test_the_cli_runs_with_crashes_and_reports_them(capsys):
    assert main(["emulate", "--ports", "0", "0", "--period", "0.02", "--crash-every", "0.2",
                 "--crash-down", "0.05", "--duration", "1.5"]) == 0
    out = capsys.readouterr().out
    assert "node1 127.0.0.1:" in out and "dropped_restart" in out
    crashed = [line for line in out.splitlines() if line.startswith("DESERT crashed")]
    assert crashed and int(crashed[0].split()[2]) >= 1
