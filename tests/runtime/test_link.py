"""Link façade: offer -> paced frames -> (echoing server) -> decoded, reassembled payloads."""
from __future__ import annotations

import json
import logging
import random
import threading

import pytest

from uwgen.manifest.model import LinkConfig, LinkPolicy
from uwgen.runtime.link.connection import Backoff
from uwgen.runtime.wire.framing import FrameDecoder, encode_frame
from uwgen.runtime.link.link import Link

from .tcp_server import TinyServer, wait_until

pytestmark = pytest.mark.timeout(30)

FAST = LinkConfig(max_read_length=64, period=0.01)


def payload(key: int, n: int, size: int) -> bytes:
    return bytes((0, key)) + n.to_bytes(4, "big") + random.Random(n).randbytes(size - 6)


class Collector:
    def __init__(self):
        self.items: list[bytes] = []
        self.lock = threading.Lock()

    def __call__(self, p: bytes) -> None:
        with self.lock:
            self.items.append(p)


def make_link(port, collector, **kw) -> Link:
    kw.setdefault("config", FAST)
    return Link(port=port, on_payload=collector, name="vehicle", rng=random.Random(4),
                backoff=Backoff(initial=0.01, maximum=0.05, rng=random.Random(1)), **kw)


@pytest.fixture
def echo():
    s = TinyServer(echo=True).start()
    yield s
    s.stop()


def test_payloads_go_out_and_come_back_in_order(echo):
    got = Collector()
    link = make_link(echo.port, got)
    link.add_channel(7, LinkPolicy(queue="fifo", depth=50))
    sent = [payload(7, n, 20) for n in range(30)]
    link.start()
    try:
        assert all(link.offer(7, p) for p in sent)
        assert wait_until(lambda: len(got.items) == 30)
        assert got.items == sent
    finally:
        link.stop()
    s = link.stats()
    assert s["channels"][7]["sent"] == 30 and s["connection"]["frames_received"] == 30
    assert s["payloads_delivered"] == 30


def test_large_payloads_are_fragmented_and_reassembled(echo):
    got = Collector()
    link = make_link(echo.port, got, fragment_id=250)
    link.add_channel(7, LinkPolicy(queue="fifo", depth=10))
    link.add_channel(4, LinkPolicy(queue="latest", priority=10))
    big = [payload(7, n, size) for n, size in enumerate((256, 1000, 3000))]
    link.start()
    try:
        for p in big:
            assert link.offer(7, p)
        link.offer(4, payload(4, 99, 22))
        assert wait_until(lambda: len(got.items) == 4)
    finally:
        link.stop()
    assert [p for p in got.items if p[1] == 7] == big
    assert payload(4, 99, 22) in got.items
    s = link.stats()
    assert s["fragments"]["completed"] == 3 and s["fragments"]["pending"] == 0
    assert s["channels"][7]["fragments_sent"] == s["fragments"]["fragments"]
    # Every frame on the wire fits the format.
    frames = FrameDecoder().feed(bytes(echo.received))
    assert all(len(f) <= 255 for f in frames) and len(frames) == s["connection"]["frames_sent"]


def test_payload_over_255_without_fragment_id_is_refused_and_logged(echo, caplog):
    link = make_link(echo.port, Collector())
    link.add_channel(6, LinkPolicy(), name="/vehicle/battery")
    with caplog.at_level(logging.ERROR, logger="uwgen.link"):
        assert not link.offer(6, payload(6, 1, 300))
    assert link.stats()["channels"][6]["too_large"] == 1
    assert "/vehicle/battery" in caplog.text and "300-byte" in caplog.text


def test_without_fragment_id_fragment_like_payloads_pass_through(echo):
    got = Collector()
    link = make_link(echo.port, got)
    link.add_channel(250, LinkPolicy())
    odd = bytes.fromhex("00 18 FA 00 00 02 41 00")   # looks like a fragment; not ours to judge
    link.start()
    try:
        link.offer(250, odd)
        assert wait_until(lambda: got.items == [odd])
    finally:
        link.stop()


def test_received_garbage_and_unknown_fragments_do_not_reach_the_handler(echo):
    got = Collector()
    link = make_link(echo.port, got, fragment_id=250)
    link.start()
    try:
        assert wait_until(lambda: echo.has_client)
        echo.send(b"\x01\x02" + encode_frame(bytes.fromhex("00 18 FA 00 00 02 41 00"))   # 1 of 2
                  + encode_frame(bytes.fromhex("00 18 FA 00")) + encode_frame(b"\x00\x05ok"))
        assert wait_until(lambda: got.items == [b"\x00\x05ok"])
    finally:
        link.stop()
    f = link.stats()["fragments"]
    assert f["malformed"] == 1 and f["pending"] == 1


def test_stats_are_json_and_cover_the_contract():
    link = Link(port=1, config=FAST, on_payload=lambda p: None, fragment_id=250, name="surface")
    link.add_channel(4, LinkPolicy())
    link.offer(4, b"\x00\x04\x01")
    s = json.loads(json.dumps(link.stats()))
    ch = s["channels"]["4"]
    for key in ("offered", "sent", "superseded", "overflow", "expired", "rate_limited", "too_large", "queued"):
        assert key in ch
    conn = s["connection"]
    for key in ("frames_sent", "frames_received", "frames_dropped", "reconnects", "bytes_sent",
                "bytes_received", "connected"):
        assert key in conn
    assert ch["offered"] == 1 and ch["queued"] == 1 and s["connected"] is False


def test_messages_wait_in_our_queue_while_disconnected_and_policy_applies():
    got = Collector()
    with TinyServer(echo=True) as server:
        port = server.port
    link = make_link(port, got)
    link.add_channel(4, LinkPolicy(queue="latest"))
    link.start()
    try:
        for n in range(5):
            link.offer(4, payload(4, n, 10))      # DESERT is down: only the newest survives
        with TinyServer(port, echo=True):
            assert wait_until(lambda: got.items == [payload(4, 4, 10)])
    finally:
        link.stop()
    assert link.stats()["channels"][4]["superseded"] == 4


def test_fragment_id_cannot_be_a_channel():
    link = Link(port=1, config=FAST, on_payload=lambda p: None, fragment_id=250)
    with pytest.raises(ValueError, match="reserved fragment_id"):
        link.add_channel(250, LinkPolicy())
