"""The runtime's Link/DesertConnection against the emulated DESERT nodes, over real sockets.

What the link over the emulator must show end to end:
- payloads written to one node arrive at the other's client with the configured delay and
  loss, and the framing decoder recovers every intact frame (and nothing else);
- killing and restarting DESERT loses only what was in flight; the client resumes by itself;
- under a writer ten times faster than the link, DESERT's own queue stays about one period.
Links run with small periods (0.05 s) so the whole module takes a few seconds.
"""
from __future__ import annotations

import threading
import time

import pytest

from uwgen.emulator import NodeSpec, Scenario, run_emulator
from uwgen.manifest.model import LinkConfig, LinkPolicy
from uwgen.runtime.link.connection import Backoff
from uwgen.runtime.wire.framing import encode_frame
from uwgen.runtime.link.link import Link

from emulator.helpers import wait_for

pytestmark = pytest.mark.timeout(60)

PERIOD = 0.05
MRL = 64
KEY = 7
FIFO = LinkPolicy(queue="fifo", depth=10_000)


def scenario(distance: float = 150.0, **kw) -> Scenario:
    kw.setdefault("bitrate", 48_000.0)     # 64-byte packets take 11 ms: well inside a period
    return Scenario(nodes=[NodeSpec("surface", position=(0, 0, 0), dest="vehicle"),
                           NodeSpec("vehicle", position=(distance, 0, 0), dest="surface")],
                    period=PERIOD, max_read_length=MRL, **kw)


class Receiver:
    """Collects what a Link delivers, with arrival times."""

    def __init__(self):
        self.payloads: list[bytes] = []
        self.times: list[float] = []
        self._lock = threading.Lock()

    def __call__(self, payload: bytes) -> None:
        with self._lock:
            self.payloads.append(payload)
            self.times.append(time.monotonic())

    def count(self) -> int:
        with self._lock:
            return len(self.payloads)


def link(port: int, name: str, on_payload=None) -> Link:
    lk = Link(host="127.0.0.1", port=port, config=LinkConfig(max_read_length=MRL, period=PERIOD),
              on_payload=on_payload, name=name, backoff=Backoff(initial=0.02, maximum=0.2))
    lk.add_channel(KEY, FIFO)
    return lk


def payload(i: int, size: int = 21) -> bytes:
    """Distinct payloads of one size, without 0x99 or 0x55 inside: in a stream of equal frames
    cut into 64-byte packets, a lost packet can then never splice two frames into a false one
    (that needs a loss of a multiple of the 25-byte frame), so the test can demand that exactly
    the intact frames come out."""
    text = f"#{i:06d}".encode()
    return text + b"." * (size - len(text))


def intact_frames(sent: list[bytes], delivered) -> list[bytes]:
    """The payloads whose every frame byte arrived, given the emulator's delivered packets
    (each with its offset in the sender's byte stream)."""
    have = [False] * sum(len(encode_frame(p)) for p in sent)
    for d in delivered:
        for k in range(d.offset, d.offset + len(d.data)):
            have[k] = True
    out, pos = [], 0
    for p in sent:
        n = len(encode_frame(p))
        if all(have[pos:pos + n]):
            out.append(p)
        pos += n
    return out


def test_payloads_arrive_with_the_configured_delay_and_loss_and_every_intact_frame_decodes():
    per = 0.2
    sent = [payload(i) for i in range(160)]
    rx = Receiver()
    with run_emulator(scenario(distance=150.0, per=per, seed=4), record=True) as emu:
        tx = link(emu.port("surface"), "surface")
        rcv = link(emu.port("vehicle"), "vehicle", on_payload=rx)
        rcv.start()
        try:
            assert wait_for(lambda: rcv.connected, 5)
            for p in sent:                 # all queued before the first write: every write
                assert tx.offer(KEY, p)    # holds two whole 25-byte frames (packet-aligned)
            tx.start()
            # 160 frames of 25 bytes = 80 packets, one per 0.05 s: about 4.2 s.
            assert wait_for(lambda: emu.counters("surface")["bytes_in"] == 160 * 25
                              and emu.counters("surface")["queue_bytes"] == 0, 15)
            time.sleep(0.3)
            delivered = emu.deliveries("vehicle")
            counters = emu.counters("vehicle")
            sent_packets = emu.counters("surface")["packets_sent"]
        finally:
            tx.stop(), rcv.stop()
    # Loss: the configured packet error rate, and nothing else.
    assert sent_packets == 160 // (MRL // 25)
    assert counters["lost_per"] + counters["packets_delivered"] == sent_packets
    assert counters["lost_per"] / sent_packets == pytest.approx(per, abs=0.1)
    assert counters["lost_collision"] == counters["lost_snr"] == counters["lost_no_client"] == 0
    # Framing: exactly the intact frames, in order, once each.
    expected = intact_frames(sent, delivered)
    assert rx.payloads == expected
    assert 0.5 * len(sent) < len(expected) < len(sent)
    # Delay: each packet left on a send tick (every PERIOD from the start) after a 10-20 ms
    # carrier listen, then took its transmission time plus 150 m / 1500 m/s to arrive.
    for d in delivered:
        on_air = (len(d.data) + 4) * 8 / 48_000.0 + 150.0 / 1500.0
        assert d.time - d.sent_at == pytest.approx(on_air, abs=1e-6)
        listen = (d.sent_at + 1e-9) % PERIOD
        assert 0.01 - 1e-6 <= listen <= 0.02 + 1e-6
        assert d.sent_at - d.queued_at >= listen


def test_restarting_desert_loses_only_what_was_in_flight_and_the_link_resumes_by_itself():
    rx = Receiver()
    sent: list[bytes] = []
    with run_emulator(scenario(distance=150.0, seed=2)) as emu:
        tx = link(emu.port("surface"), "surface")
        rcv = link(emu.port("vehicle"), "vehicle", on_payload=rx)
        tx.start(), rcv.start()
        try:
            assert wait_for(lambda: tx.connected and rcv.connected, 5)

            def offer_for(seconds: float) -> None:
                end = time.monotonic() + seconds
                while time.monotonic() < end:
                    p = payload(len(sent), size=10)
                    sent.append(p)
                    assert tx.offer(KEY, p)
                    time.sleep(0.03)     # 14-byte frames every 30 ms: below the link's rate

            offer_for(1.0)
            emu.restart(delay=0.3)
            offer_for(1.5)
            assert wait_for(lambda: tx.connected and rcv.connected, 5)
            assert wait_for(lambda: rx.count() >= len(sent) - _lost_bound(emu), 10)
            time.sleep(0.5)
            dropped = emu.counters("surface")["dropped_restart"]
            reconnects = (tx.stats()["connection"]["reconnects"],
                          rcv.stats()["connection"]["reconnects"])
            abandoned = tx.stats()["connection"]["frames_dropped"]["abandoned"]
        finally:
            tx.stop(), rcv.stop()
    assert reconnects[0] >= 1 and reconnects[1] >= 1        # both clients came back alone
    got = rx.payloads
    assert len(got) == len(set(got))                          # nothing twice
    assert got == [p for p in sent if p in set(got)]          # in order
    lost = len(sent) - len(got)
    # Lost: the frames touched by the packets DESERT dropped (queued or in flight), the frame
    # the link had cut when the connection went, and at most one write that reached the socket
    # after the restart closed it.
    assert lost <= _lost_bound(emu, dropped + 1) + abandoned
    # And what was offered after the restart arrived.
    assert got[-1] == sent[-1]


def _lost_bound(emu, dropped: int | None = None) -> int:
    """Frames of 14 bytes that `dropped` packets of at most 64 bytes can hold (4.6 each)."""
    if dropped is None:
        dropped = emu.counters("surface")["dropped_restart"]
    return dropped * (MRL // 14 + 1) + 2


def test_a_writer_ten_times_faster_than_the_link_never_fills_desert_beyond_one_period():
    rx = Receiver()
    with run_emulator(scenario(distance=15.0, seed=3)) as emu:
        tx = link(emu.port("surface"), "surface")
        rcv = link(emu.port("vehicle"), "vehicle", on_payload=rx)
        tx.start(), rcv.start()
        try:
            assert wait_for(lambda: tx.connected and rcv.connected, 5)
            # The link carries 64 B per 0.05 s = 1280 B/s; offer 12800 B/s for 2 s.
            offered, samples = 0, []
            start = time.monotonic()
            while time.monotonic() - start < 2.0:
                for _ in range(8):
                    tx.offer(KEY, payload(offered, size=16))
                    offered += 1
                time.sleep(0.0125)         # 8 x 20-byte frames per 12.5 ms = 12.8 kB/s
                samples.append(emu.counters("surface")["queue_bytes"])
            peak = emu.counters("surface")["max_queue_bytes"]
            channel = tx.stats()["channels"][KEY]
        finally:
            tx.stop(), rcv.stop()
    # DESERT's unbounded queue held at most about one period's worth (one or two packets)...
    assert peak <= 2 * MRL
    assert max(samples) <= 2 * MRL
    # ...because the backlog waited in the link's own queue, where policy can act on it.
    assert channel["queued"] + channel["overflow"] > offered // 2
    assert channel["sent"] <= 2.2 * 1280 / 20 + 8
    assert rx.count() > 0
