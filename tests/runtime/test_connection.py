"""DesertConnection against a tiny TCP server on 127.0.0.1: connect, reconnect, pacing, no duplicates."""
from __future__ import annotations

import logging
import random
import threading
import time
from collections import deque

import pytest

from uwgen.manifest.model import LinkConfig
from uwgen.runtime.link.connection import LOUD_RETRIES, Backoff, DesertConnection
from uwgen.runtime.wire.framing import FrameDecoder, encode_frame

from .tcp_server import TinyServer, free_port, wait_until

pytestmark = pytest.mark.timeout(30)

FAST = LinkConfig(max_read_length=64, period=0.02)


class Source:
    """Numbered payloads, either a fixed list or an endless flood."""

    def __init__(self, count: int | None = None, size: int = 20):
        self.n, self.count, self.size = 0, count, size
        self.lock = threading.Lock()

    def __call__(self, now: float) -> bytes | None:
        with self.lock:
            if self.count is not None and self.n >= self.count:
                return None
            self.n += 1
            return b"\x00\x07" + self.n.to_bytes(4, "big") + bytes(self.size - 6)


def serials(stream: bytes) -> list[int]:
    return [int.from_bytes(p[2:6], "big") for p in FrameDecoder().feed(bytes(stream))]


def quick_backoff() -> Backoff:
    return Backoff(initial=0.01, maximum=0.05, rng=random.Random(1))


def make(port, source=None, on_frame=None, config=FAST, **kw) -> DesertConnection:
    return DesertConnection("127.0.0.1", port, config, source=source or (lambda now: None),
                            on_frame=on_frame or (lambda p: None), name="test",
                            backoff=kw.pop("backoff", quick_backoff()), **kw)


@pytest.fixture
def server():
    s = TinyServer().start()
    yield s
    s.stop()


def test_sends_frames_and_delivers_received_payloads(server):
    got = []
    conn = make(server.port, source=Source(count=10), on_frame=got.append)
    conn.start()
    try:
        assert wait_until(lambda: len(serials(server.received)) == 10)
        assert serials(server.received) == list(range(1, 11))
        server.send(encode_frame(b"\x00\x04hi") + b"junk" + encode_frame(b"\x00\x05yo"))
        assert wait_until(lambda: len(got) == 2)
        assert got == [b"\x00\x04hi", b"\x00\x05yo"]
        s = conn.stats()
        assert s["connected"] and s["frames_sent"] == 10 and s["frames_received"] == 2
        assert s["bytes_received"] == 2 * 8 + 4 and s["bytes_discarded"] == 4
        assert s["connects"] == 1 and s["reconnects"] == 0
    finally:
        conn.stop()


def test_waits_for_desert_that_is_not_listening_yet():
    port = free_port()
    conn = make(port, source=Source(count=3))
    conn.start()
    try:
        assert wait_until(lambda: conn.stats()["connect_failures"] >= 3)
        assert not conn.connected
        with TinyServer(port) as server:
            assert wait_until(lambda: len(serials(server.received)) == 3)
            assert serials(server.received) == [1, 2, 3]   # nothing lost while waiting to connect
            assert conn.connected
    finally:
        conn.stop()


def test_reconnects_when_desert_restarts_and_delivers_nothing_twice(server):
    src = Source(size=30)
    conn = make(server.port, source=src)
    conn.start()
    try:
        assert wait_until(lambda: len(serials(server.received)) >= 20)
        with server._lock:
            before = bytes(server.received)
            server.received.clear()
        server.restart(down_for=0.1)
        assert wait_until(lambda: conn.stats()["reconnects"] == 1)
        assert wait_until(lambda: len(serials(server.received)) >= 20)
        after = bytes(server.received)
    finally:
        conn.stop()
    a, b = serials(before), serials(after)
    assert a == sorted(set(a)) and b == sorted(set(b))
    assert not set(a) & set(b), "a frame was delivered twice"
    assert b[0] > a[-1]
    s = conn.stats()
    assert s["disconnects"] == 1
    # Frames the source handed out = sent + cut by the disconnect + lost in flight + waiting.
    assert s["frames_dropped"]["abandoned"] <= 2


def test_reconnects_when_desert_closes_the_connection(server):
    conn = make(server.port)
    conn.start()
    try:
        assert wait_until(lambda: conn.connected and server.has_client)
        server.kick()
        assert wait_until(lambda: conn.stats()["reconnects"] == 1)
        assert wait_until(lambda: conn.connected)
        assert wait_until(lambda: server.clients == 2)
    finally:
        conn.stop()


def test_survives_desert_dying_while_writing_without_sigpipe():
    # Writes into a connection the peer has closed raise EPIPE/ECONNRESET (never SIGPIPE: the
    # whole test process would die); the connection counts a disconnect and keeps retrying.
    server = TinyServer().start()
    conn = make(server.port, source=Source(size=200), config=LinkConfig(max_read_length=4096, period=0.001))
    conn.start()
    try:
        assert wait_until(lambda: len(server.received) > 10000)
        server.stop()
        assert wait_until(lambda: conn.stats()["disconnects"] >= 1)
        assert wait_until(lambda: conn.stats()["connect_failures"] >= 1)
        assert conn._thread.is_alive()
    finally:
        conn.stop()


def test_writes_no_faster_than_the_link_carries(server):
    config = LinkConfig(max_read_length=64, period=0.05)
    conn = make(server.port, source=Source(size=40), config=config)    # an endless flood
    conn.start()
    try:
        assert wait_until(lambda: server.reads)
        t0 = server.reads[0][0]
        time.sleep(1.0)
        reads = list(server.reads)
    finally:
        conn.stop()
    elapsed = reads[-1][0] - t0
    total = sum(n for _, n in reads)
    # One write of at most 64 bytes per 50 ms: the total can exceed that budget by one write only.
    assert total <= config.max_read_length * (elapsed / config.period + 1)
    assert total >= 0.4 * config.max_read_length * (elapsed / config.period)   # and uses the link


def test_gives_up_a_frame_whose_tail_never_comes(server):
    got = []
    conn = make(server.port, on_frame=got.append, stall_timeout=0.1)
    conn.start()
    try:
        assert wait_until(lambda: server.has_client)
        # A start whose LEN promises 240 bytes that were lost, then a good frame, then silence.
        server.send(bytes.fromhex("99 99 F0 00 04") + encode_frame(b"\x00\x05ok"))
        assert wait_until(lambda: got == [b"\x00\x05ok"], timeout=2)
        assert conn.stats()["frames_dropped"]["stalled"] == 1
    finally:
        conn.stop()


def test_handler_errors_are_counted_and_the_link_goes_on(server):
    got = []

    def handler(p):
        if p == b"bad":
            raise RuntimeError("boom")
        got.append(p)

    conn = make(server.port, on_frame=handler)
    conn.start()
    try:
        assert wait_until(lambda: server.has_client)
        server.send(encode_frame(b"bad") + encode_frame(b"good"))
        assert wait_until(lambda: got == [b"good"])
        assert conn.stats()["frames_dropped"]["callback_errors"] == 1
    finally:
        conn.stop()


def test_unframeable_payload_is_dropped_and_counted(server):
    items = deque([b"x" * 300, b"", b"\x00\x07ok"])
    conn = make(server.port, source=lambda now: items.popleft() if items else None)
    conn.start()
    try:
        assert wait_until(lambda: bytes(server.received) == encode_frame(b"\x00\x07ok"))
        assert conn.stats()["frames_dropped"]["unframeable"] == 2
    finally:
        conn.stop()


def test_connection_failures_are_logged_a_few_times_not_every_retry(caplog):
    conn = make(free_port(), backoff=Backoff(initial=0.001, maximum=0.002, rng=random.Random(2)))
    with caplog.at_level(logging.INFO, logger="uwgen.link"):
        conn.start()
        try:
            assert wait_until(lambda: conn.stats()["connect_failures"] >= 30)
        finally:
            conn.stop()
    lines = [r.getMessage() for r in caplog.records if r.name == "uwgen.link"]
    assert len(lines) == LOUD_RETRIES + 1
    assert "retrying in" in lines[0] and "without logging" in lines[-1]


def test_state_changes_are_logged_once(caplog, server):
    conn = make(server.port)
    with caplog.at_level(logging.INFO, logger="uwgen.link"):
        conn.start()
        try:
            assert wait_until(lambda: conn.connected and server.has_client)
            server.kick()
            assert wait_until(lambda: conn.stats()["reconnects"] == 1)
        finally:
            conn.stop()
    lines = [r.getMessage() for r in caplog.records if r.name == "uwgen.link"]
    assert [m.split(" DESERT")[0] for m in lines] == ["[test] connected to", "[test] disconnected from",
                                                      "[test] connected to"]


def test_stop_is_prompt_while_retrying():
    conn = make(free_port(), backoff=Backoff(initial=5, maximum=5))
    conn.start()
    assert wait_until(lambda: conn.stats()["connect_failures"] >= 1)
    t = time.monotonic()
    conn.stop()
    assert time.monotonic() - t < 1.0
    assert not conn._thread.is_alive()


# -- backoff ------------------------------------------------------------------------------------

def test_backoff_grows_exponentially_up_to_the_maximum():
    b = Backoff(initial=0.1, maximum=2.0, factor=2.0, jitter=0.0)
    assert [round(b.next_delay(), 6) for _ in range(7)] == [0.1, 0.2, 0.4, 0.8, 1.6, 2.0, 2.0]
    b.reset()
    assert b.next_delay() == 0.1


def test_backoff_jitter_is_bounded_and_repeatable_with_a_seed():
    def delays(seed):
        b = Backoff(initial=1.0, maximum=1.0, jitter=0.5, rng=random.Random(seed))
        return [b.next_delay() for _ in range(50)]
    d = delays(7)
    assert d == delays(7) and d != delays(8)
    assert all(0.5 <= x <= 1.0 for x in d)


@pytest.mark.parametrize("kw", [dict(initial=0), dict(initial=2, maximum=1), dict(jitter=1.0), dict(factor=0.5)])
def test_backoff_refuses_nonsense(kw):
    with pytest.raises(ValueError):
        Backoff(**kw)


def test_server_that_accepts_and_closes_at_once_causes_no_spin_and_no_log_flood(caplog):
    import socket

    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(8)
    listener.settimeout(0.05)
    running = True

    def slam():
        while running:
            try:
                c, _ = listener.accept()
            except OSError:
                continue
            c.close()

    t = threading.Thread(target=slam, daemon=True)
    t.start()
    conn = make(listener.getsockname()[1], backoff=Backoff(initial=0.01, maximum=0.05, rng=random.Random(3)))
    try:
        with caplog.at_level(logging.INFO, logger="uwgen.link"):
            conn.start()
            time.sleep(1.0)
            conn.stop()
    finally:
        running = False
        t.join(2)
        listener.close()
    stats = conn.stats()
    assert stats["connects"] == 0 and not stats["connected"]      # never proved itself
    assert 5 <= stats["unproven"] <= 1.0 / 0.025 + 5   # backed off between attempts: no tight loop
    lines = [r.getMessage() for r in caplog.records if r.name == "uwgen.link"]
    assert 1 <= len(lines) <= 3                        # the 1st, 10th (and 100th): no flood
    assert all("accepted the connection and closed it before it proved itself" in m for m in lines)


def test_wake_ups_are_coalesced_until_the_thread_takes_them():
    conn = make(free_port())
    try:
        for _ in range(100):
            conn.wake()                 # 100 offers while the thread is busy or not started
        assert conn._wake_r.recv(4096) == b"\0"   # one byte, one wake-up, not 100
        conn._woken = False             # what the thread does when it takes the byte
        conn.wake()
        assert conn._wake_r.recv(4096) == b"\0"
    finally:
        conn.stop()


def test_a_packet_ready_after_its_turn_is_over_is_not_written_but_counted(server, caplog):
    """The MAC says the packet just built came too late for its turn (a stalled thread:
    mac_base.Mac.late): the connection drops it, tells the MAC, counts and logs it, and
    writes the next one."""
    from uwgen.runtime.link.mac_base import Mac

    class Stalled(Mac):
        def __init__(self):
            super().__init__()
            self.asked, self.dropped, self.written = 0, 0, 0

        def late(self, now):
            self.asked += 1
            return self.asked == 1                    # the first packet only

        def abandoned(self):
            self.dropped += 1

        def wrote(self, now, nbytes):
            self.written += 1
    mac = Stalled()
    conn = make(server.port, source=Source(count=3), mac=mac, one_frame=True)   # a packet a write
    with caplog.at_level(logging.WARNING, logger="uwgen.link"):
        conn.start()
        try:
            assert wait_until(lambda: len(serials(server.received)) == 2)
            time.sleep(0.1)
            assert serials(server.received) == [2, 3]
            assert (mac.dropped, mac.written) == (1, 2)
            assert conn.stats()["frames_dropped"]["late"] == 1
        finally:
            conn.stop()
    assert any("was not written" in r.getMessage() for r in caplog.records)
