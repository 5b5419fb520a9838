"""Small fakes that follow notes/contracts.md: a codec table and a link pair.

The fake codecs carry a message as its CDR bytes (rclpy's own serializer) inside the real
payload header `[kind, id, (seq,) bytes]`, so bridge logic is tested without depending on
generated code. The fake link delivers what one side offers to the other side's
`on_payload`, from a thread of its own as the real link does, and can mute, delay or
duplicate deliveries.
"""
from __future__ import annotations

import queue
import threading
import time
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import ros_domains  # tests/ros_domains.py

from rclpy.serialization import deserialize_message, serialize_message

from uwgen.manifest.model import LinkConfig, LinkPolicy, Qos, Side
from uwgen.runtime.wire.codec import DecodeError, EncodeError, load_items, pack_items


def _load(payload: bytes, kind: int, ident: int, with_seq: bool) -> list:
    items = load_items(payload)
    n = 3 if with_seq else 2
    if len(items) != n + 1 or items[0] != kind or items[1] != ident or type(items[-1]) is not bytes:
        raise DecodeError("", f"not a fake payload of kind {kind} id {ident}")
    return items


@dataclass
class FakeTopicCodec:
    id: int
    name: str
    cls: Any
    publisher: str
    policy: LinkPolicy = field(default_factory=LinkPolicy)
    qos: Qos = field(default_factory=Qos)
    profile: str = "native"
    max_len: int | None = None   # encode refuses longer payloads (to test encode errors)

    @property
    def type_name(self) -> str:
        if self.cls is None:
            return "fake/msg/Missing"
        return f"{self.cls.__module__.split('.')[0]}/msg/{self.cls.__name__}"

    def ros_class(self):
        if self.cls is None:
            raise DecodeError("", "rclpy class fake.Missing is not importable here")
        return self.cls

    def encode(self, msg) -> bytes:
        data = pack_items([0, self.id, serialize_message(msg)])
        if self.max_len is not None and len(data) > self.max_len:
            raise EncodeError("data", f"payload of {len(data)} bytes over {self.max_len}")
        return data

    def decode(self, payload: bytes, ros: bool = True):
        try:
            return deserialize_message(_load(payload, 0, self.id, False)[-1], self.cls)
        except DecodeError:
            raise
        except Exception as exc:
            raise DecodeError("", str(exc)) from None


@dataclass
class FakeServiceCodec:
    id: int
    name: str
    cls: Any
    server: str
    timeout: float = 10.0
    policy: LinkPolicy = field(default_factory=lambda: LinkPolicy(queue="fifo", depth=4))
    profile: str = "native"

    @property
    def type_name(self) -> str:
        return f"{self.cls.__module__.split('.')[0]}/srv/{self.cls.__name__}"

    def ros_class(self):
        return self.cls

    def encode_request(self, seq: int, req) -> bytes:
        return pack_items([2, self.id, seq, serialize_message(req)])

    def encode_response(self, seq: int, resp) -> bytes:
        return pack_items([3, self.id, seq, serialize_message(resp)])

    def decode_request(self, payload: bytes, ros: bool = True):
        items = _load(payload, 2, self.id, True)
        return items[2], deserialize_message(items[3], self.cls.Request)

    def decode_response(self, payload: bytes, ros: bool = True):
        items = _load(payload, 3, self.id, True)
        return items[2], deserialize_message(items[3], self.cls.Response)


def fake_package(topics, services=(), network="fake", fragment_id=250,
                 ports=(4000, 4001)) -> SimpleNamespace:
    sides = {name: Side(name=name, port=port, link=LinkConfig(64, 0.2))
             for name, port in zip(("surface", "vehicle"), ports)}
    return SimpleNamespace(
        MANIFEST=SimpleNamespace(network=network, sides=sides, fragment_id=fragment_id,
                                 profile="native"),
        TOPICS={t.id: t for t in topics}, SERVICES={s.id: s for s in services})


class FakeLink:
    """One side's link. `peer` receives what this side offers (if not muted)."""

    def __init__(self, host, port, config, on_payload, fragment_id=None, clock=None, name="",
                 **wire):
        self.host, self.port, self.config, self.name = host, port, config, name
        self.on_payload = on_payload
        self.fragment_id = fragment_id
        self.channels: dict[int, LinkPolicy] = {}
        self.whole: dict[int, bool] = {}   # channels added whole (never fragmented)
        self.offers: list[tuple[int, bytes]] = []
        self.peer: FakeLink | None = None
        self.accept = True
        self.mute = False          # offered payloads are accepted but never delivered
        self.delay = 0.0           # seconds before delivery
        self.duplicate = False     # deliver every payload twice
        self.started = self.stopped = False
        self.connects = 1          # what stats() reports as the connection's connect count
        self.offered_after_stop = 0
        self._q: queue.Queue = queue.Queue()
        self._thread = threading.Thread(target=self._deliver_loop, name=f"fakelink-{name}",
                                        daemon=True)

    def add_channel(self, key: int, policy: LinkPolicy, name: str | None = None, *,
                    whole: bool = False) -> None:
        self.channels[key] = policy
        self.whole[key] = whole

    def offer(self, key: int, payload: bytes, published: float | None = None) -> bool:
        if key not in self.channels or not self.accept:
            return False
        if self.stopped:
            self.offered_after_stop += 1
        self.offers.append((key, payload))
        if self.peer is not None and not self.mute:
            for _ in range(2 if self.duplicate else 1):
                self.peer._q.put((time.monotonic() + self.delay, payload))
        return True

    def queued(self, key: int) -> int:
        """Nothing waits: an offer is handed to the peer at once."""
        return 0

    def inject(self, payload: bytes) -> None:
        """Deliver `payload` to this side's bridge as if it came over the link."""
        self._q.put((0.0, payload))

    def _deliver_loop(self) -> None:
        while True:
            item = self._q.get()
            if item is None:
                return
            when, payload = item
            wait = when - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            self.on_payload(payload)

    def start(self) -> None:
        self.started = True
        self._thread.start()

    def stop(self) -> None:
        self.stopped = True
        self._q.put(None)

    def stats(self) -> dict:
        counts: dict[int, int] = {}
        for key, _ in self.offers:
            counts[key] = counts.get(key, 0) + 1
        return {"connected": True, "connection": {"connects": self.connects},
                "channels": {k: {"offered": counts.get(k, 0), "sent": counts.get(k, 0)}
                             for k in self.channels}}

    def offered(self, key: int) -> list[bytes]:
        """Payloads offered on channel `key`, in order."""
        return [p for k, p in list(self.offers) if k == key]


class LinkPair:
    """Factory for two fake links wired to each other, keyed by side name."""

    def __init__(self):
        self.links: dict[str, FakeLink] = {}

    def factory(self, **kwargs) -> FakeLink:
        link = FakeLink(**kwargs)
        self.links[link.name] = link
        others = [l for n, l in self.links.items() if n != link.name]
        for other in others:
            other.peer, link.peer = link, other
        return link


class FakeSubscription:
    """rclpy's subscription handle as the bridge takes from it, holding `queued` messages:
    TopicBridge takes a burst as the subscription was made (`raw` False), the poller takes
    serialized messages (`raw` True: only the newest is deserialized). A message info
    without a publication time comes with each."""

    def __init__(self, queued, msg_type, topic_name: str, raw: bool):
        self.queued, self.msg_type, self.topic_name, self.raw = list(queued), msg_type, topic_name, raw
        self.handle = self

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def take_message(self, msg_type, raw):
        assert raw == self.raw, f"taken with raw={raw}, as the subscription was not made"
        if not self.queued:
            return None
        msg = self.queued.pop(0)
        return (serialize_message(msg) if raw else msg), {}


def next_domain() -> int:
    """A ROS domain id of its own for every context a test creates (tests/ros_domains.py)."""
    return ros_domains.next_domain()


def wait_for(cond, timeout: float = 10.0, what: str = "condition") -> None:
    """Poll `cond` until true or fail after `timeout` seconds (no fixed sleeps in tests)."""
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.01)
