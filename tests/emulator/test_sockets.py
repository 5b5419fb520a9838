"""The emulator behind real TCP sockets on 127.0.0.1 (small periods so they stay fast)."""
from __future__ import annotations

import os
import socket
import time

import pytest

from uwgen.emulator import Emulator, EmulatorError, NodeSpec, Scenario, run_emulator

from .helpers import connect, fast_link, recv_exactly, wait_for

pytestmark = pytest.mark.timeout(30)


def test_bytes_written_to_one_node_arrive_unchanged_at_the_other():
    data = os.urandom(1000)
    with run_emulator(fast_link(max_read_length=64), record=True) as emu:
        a, b = connect(emu.port("a")), connect(emu.port("b"))
        assert wait_for(lambda: emu.counters("b")["client_connected"] == 1)
        a.sendall(data)
        assert recv_exactly(b, len(data)) == data
        recorded = emu.deliveries("b")
        assert b"".join(d.data for d in recorded) == data
        assert [d.offset for d in recorded] == sorted(d.offset for d in recorded)
        assert all(len(d.data) <= 64 and d.source == "a" for d in recorded)
        ca, cb = emu.counters("a"), emu.counters("b")
        assert ca["bytes_in"] == 1000 and ca["packets_queued"] >= 16
        assert cb["bytes_delivered"] == 1000 and cb["packets_delivered"] == ca["packets_sent"]
        a.close(), b.close()


def test_both_directions_work_at_once():
    with run_emulator(fast_link()) as emu:
        a, b = connect(emu.port("a")), connect(emu.port("b"))
        assert wait_for(lambda: emu.counters("a")["client_connected"] == 1
                        and emu.counters("b")["client_connected"] == 1)
        a.sendall(b"ping" * 10)
        b.sendall(b"pong" * 10)
        assert recv_exactly(b, 40) == b"ping" * 10
        assert recv_exactly(a, 40) == b"pong" * 10
        a.close(), b.close()


def test_packets_leave_one_per_period_in_real_time():
    scen = fast_link(period=0.05, max_read_length=10)
    with run_emulator(scen) as emu:
        a, b = connect(emu.port("a")), connect(emu.port("b"))
        assert wait_for(lambda: emu.counters("b")["client_connected"] == 1)
        start = time.monotonic()
        a.sendall(bytes(60))                 # six packets: at least five periods
        recv_exactly(b, 60)
        elapsed = time.monotonic() - start
        assert 5 * 0.05 <= elapsed < 6 * 0.05 + 0.5
        a.close(), b.close()


def test_a_second_client_waits_until_the_first_disconnects():
    with run_emulator(fast_link()) as emu:
        first = connect(emu.port("b"))
        assert wait_for(lambda: emu.counters("b")["clients"] == 1)
        second = connect(emu.port("b"))        # the kernel accepts it; DESERT does not serve it
        a = connect(emu.port("a"))
        a.sendall(b"for-first")
        assert recv_exactly(first, 9) == b"for-first"
        second.settimeout(0.2)
        with pytest.raises(socket.timeout):
            second.recv(100)
        second.sendall(b"queued-by-second")    # written while waiting: read once served
        time.sleep(0.1)
        assert emu.counters("b")["bytes_in"] == 0
        first.close()
        assert wait_for(lambda: emu.counters("b")["clients"] == 2)
        assert wait_for(lambda: emu.counters("b")["bytes_in"] == 16)
        assert recv_exactly(a, 16) == b"queued-by-second"
        a.sendall(b"for-second")
        assert recv_exactly(second, 10) == b"for-second"
        a.close(), second.close()


def test_bytes_for_a_node_without_client_are_dropped_not_replayed():
    with run_emulator(fast_link(max_read_length=64)) as emu:
        a = connect(emu.port("a"))
        a.sendall(b"nobody-hears-this")
        assert wait_for(lambda: emu.counters("b")["lost_no_client"] == 1)
        b = connect(emu.port("b"))
        assert wait_for(lambda: emu.counters("b")["client_connected"] == 1)
        a.sendall(b"fresh")
        assert recv_exactly(b, 5) == b"fresh"
        b.settimeout(0.15)
        with pytest.raises(socket.timeout):
            b.recv(100)
        a.close(), b.close()


def test_restart_disconnects_clients_drops_in_flight_and_listens_on_the_same_ports():
    scen = fast_link(period=0.05, max_read_length=10)
    with run_emulator(scen) as emu:
        ports = emu.ports()
        a, b = connect(emu.port("a")), connect(emu.port("b"))
        assert wait_for(lambda: emu.counters("b")["client_connected"] == 1)
        a.sendall(bytes(200))                  # 20 packets: most still queued at the restart
        recv_exactly(b, 10)
        emu.restart(delay=0.5, wait=False)
        b.settimeout(2)
        got = b""
        while True:                            # the client sees the disconnect
            try:
                chunk = b.recv(1000)
            except ConnectionResetError:
                break
            if not chunk:
                break
            got += chunk
        with pytest.raises(OSError):           # nobody listens during the delay
            socket.create_connection(("127.0.0.1", ports["b"]), timeout=1).close()
        assert emu.wait_listening(timeout=3)
        assert emu.ports() == ports
        counters = emu.counters("a")
        assert counters["dropped_restart"] > 0
        assert counters["dropped_restart"] + emu.counters("b")["packets_delivered"] == 20
        a2, b2 = connect(ports["a"]), connect(ports["b"])
        assert wait_for(lambda: emu.counters("b")["client_connected"] == 1)
        a2.sendall(b"after-restart")
        assert recv_exactly(b2, 13) == b"after-restart"
        assert emu.restarts == 1
        for s in (a, b, a2, b2):
            s.close()


def test_start_delay_refuses_connections_until_desert_starts():
    scen = Scenario(nodes=[NodeSpec("a"), NodeSpec("b")], period=0.02, bitrate=200_000.0,
                    start_delay=0.3)
    with run_emulator(scen) as emu:
        port = emu.port("a")
        assert port != 0
        with pytest.raises(OSError):
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
        assert emu.wait_listening(timeout=3)
        connect(port).close()


def test_a_taken_port_is_a_clear_error():
    with run_emulator(fast_link()) as emu:
        taken = emu.port("a")
        scen = Scenario(nodes=[NodeSpec("x", port=taken), NodeSpec("y")])
        with pytest.raises(EmulatorError, match=f"node x: cannot listen on 127.0.0.1:{taken}"):
            Emulator(scen).start()


def test_stop_closes_everything_and_keeps_counters_readable():
    emu = run_emulator(fast_link())
    port = emu.port("a")
    a = connect(port)
    a.sendall(b"hi")
    assert wait_for(lambda: emu.counters("a")["bytes_in"] == 2)
    emu.stop()
    a.settimeout(2)
    try:
        assert a.recv(10) == b""
    except ConnectionResetError:
        pass
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", port), timeout=1).close()
    assert emu.counters("a")["bytes_in"] == 2
    with pytest.raises(EmulatorError):
        emu.restart()
    with pytest.raises(EmulatorError, match="record=True"):
        emu.deliveries()
    a.close()


def test_a_held_delivery_reaches_its_client_that_much_later_and_the_rest_on_time():
    with run_emulator(fast_link(period=0.05, max_read_length=10)) as emu:
        a, b = connect(emu.port("a")), connect(emu.port("b"))
        assert wait_for(lambda: emu.counters("b")["client_connected"] == 1)
        with pytest.raises(ValueError):
            emu.hold("b", 1.0)                       # neither a window nor a count
        emu.hold("b", 1.5, count=1)
        start = time.monotonic()
        a.sendall(b"heldheld10")                     # one packet: held 1.5 s
        time.sleep(0.3)
        a.sendall(b"onthetime!")                     # the next: on time, so it comes first
        assert recv_exactly(b, 10) == b"onthetime!"
        assert recv_exactly(b, 10) == b"heldheld10" and time.monotonic() - start >= 1.5
        assert emu.held("b") == 1 and emu.held("a") == 0
        emu.hold("a", 0.5, window=0.5)               # everything to a within 0.5 s
        b.sendall(b"x" * 20)
        t0 = time.monotonic()
        assert recv_exactly(a, 20) == b"x" * 20 and time.monotonic() - t0 >= 0.5
        assert emu.held("a") == 2
        a.close(), b.close()
