"""The guard inside the link: protected whole before fragmentation, checked after reassembly;
a payload that cannot be protected is dropped and counted, never sent in the clear."""
from __future__ import annotations

from uwgen.manifest.model import LinkConfig, LinkPolicy
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.codec import pack_items
from uwgen.runtime.link.link import Link

from .helpers import KEY, config, log_line, surface, twist, vehicle


def links(tmp_path):
    clock = ManualClock()
    got: list[bytes] = []
    sg = surface(tmp_path, clock=clock)
    s = Link(config=LinkConfig(), fragment_id=250, clock=clock, name="surface", guard=sg)
    v = Link(config=LinkConfig(), fragment_id=250, clock=clock, name="vehicle",
             guard=vehicle(tmp_path, clock=clock), on_payload=got.append)
    for key in (4, 7):
        s.add_channel(key, LinkPolicy(queue="fifo", depth=8))
    return s, v, got


def carry(s: Link, v: Link) -> list[bytes]:
    """Move every frame the sender would write now to the receiver; return them."""
    frames = []
    while (picked := s.scheduler.next_payload(0.0)) is not None:
        frames.append(picked[1])
        v._on_frame(picked[1])
    return frames


def test_a_long_payload_is_protected_whole_then_fragmented(tmp_path):
    s, v, got = links(tmp_path)
    long_log = log_line("x" * 600)
    assert s.offer(7, long_log) and s.offer(4, twist(2.0))
    frames = carry(s, v)
    fragments = [f for f in frames if f.startswith(bytes([0, 0x18, 250]))]
    assert len(frames) == len(fragments) + 1 and len(fragments) >= 3     # fragments + cmd_vel
    assert all(len(f) <= 255 for f in frames)
    assert got == [long_log, twist(2.0)] or got == [twist(2.0), long_log]
    assert v.stats()["security"]["verified"] == 2
    assert s.stats()["security"]["protected"] == 2


def test_forged_fragments_never_deliver(tmp_path):
    s, v, got = links(tmp_path)
    s.offer(7, log_line("y" * 600))
    frames = []
    while (picked := s.scheduler.next_payload(0.0)) is not None:
        frames.append(picked[1])
    last = bytearray(frames[-1])
    last[-1] ^= 0x01                                     # one bit of the tag, in the last fragment
    for f in frames[:-1] + [bytes(last)]:
        v._on_frame(f)
    assert got == [] and v.stats()["security"]["bad_tag"] == 1


def test_plain_frames_for_protected_ids_do_not_reach_the_bridge(tmp_path):
    _, v, got = links(tmp_path)
    v._on_frame(pack_items([0, 4, 1007.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    assert got == [] and v.stats()["security"]["unprotected"] == 1
    assert v.stats()["payloads_delivered"] == 0


def test_a_payload_that_cannot_be_protected_is_dropped_and_counted(tmp_path):
    s, _, _ = links(tmp_path)

    def broken(key, payload):
        raise RuntimeError("no key")
    s.scheduler.protect = broken
    assert s.offer(4, twist())
    assert s.scheduler.next_payload(0.0) is None          # nothing goes out in the clear
    chan = s.stats()["channels"][4]
    assert chan["protect_failed"] == 1 and chan["sent"] == 0 and chan["queued"] == 0


def test_size_check_counts_the_overhead(tmp_path):
    from uwgen.security.guard import LinkGuard
    g = surface(tmp_path)
    link = Link(config=LinkConfig(), fragment_id=None, guard=g)
    link.add_channel(7, LinkPolicy())
    assert not link.offer(7, log_line("z" * 240))          # fits 255 bare, not with 23 more
    assert link.stats()["channels"][7]["too_large"] == 1
    assert link.offer(7, log_line("z" * 220))
    assert isinstance(g, LinkGuard)


def test_packet_aligned_writes_weigh_the_protected_size(tmp_path):
    s, v, got = links(tmp_path)
    payload = twist(1.5)                                   # 20 bytes; 43 protected (a sync frame)
    assert s.offer(4, payload)
    assert s.scheduler.next_payload(0.0, max_size=len(payload) + 22) is None   # would not fit
    key, frame = s.scheduler.next_payload(0.0, max_size=len(payload) + 23)
    assert key == 4 and len(frame) == len(payload) + 23
    v._on_frame(frame)
    assert got == [payload]


def test_repair_fragments_of_a_protected_message_rebuild_it(tmp_path):
    from uwgen.security.guard import LinkGuard
    clock = ManualClock()
    got: list[bytes] = []
    sg = surface(tmp_path, clock=clock)
    assert isinstance(sg, LinkGuard)
    s = Link(config=LinkConfig(), fragment_id=250, clock=clock, name="surface", guard=sg)
    v = Link(config=LinkConfig(), fragment_id=250, clock=clock, name="vehicle",
             guard=vehicle(tmp_path, clock=clock), on_payload=got.append)
    s.add_channel(7, LinkPolicy(queue="fifo", depth=4, repair=2))
    long_log = log_line("r" * 300)
    assert s.offer(7, long_log)
    frames = []
    while (picked := s.scheduler.next_payload(0.0)) is not None:
        frames.append(picked[1])
    assert len(frames) >= 4
    for k, f in enumerate(frames):
        if k not in (0, 2):                                # two fragments lost on the water
            v._on_frame(f)
    assert got == [long_log]
    assert v.stats()["security"]["verified"] == 1


def test_an_actions_feedback_channel_is_protected_as_its_wire_id(tmp_path):
    # An action's feedback goes on link channel 256 + id with the action's id in its header:
    # the receiver checks the header's id, so the sender must protect by it too (found in the
    # secured demo: every feedback of its mission arrived unprotected and was dropped).
    from uwgen.bridge.plan import FEEDBACK_KEY_BASE
    from uwgen.security.guard import LinkGuard
    modes = {30: "encrypt"}
    clock = ManualClock()
    got: list[bytes] = []
    sg = LinkGuard.for_key(KEY, config(2, 1, "surface", modes), tmp_path / "v.lock", clock=clock)
    rg = LinkGuard.for_key(KEY, config(1, 2, "vehicle", modes), tmp_path / "s.lock", clock=clock)
    s = Link(config=LinkConfig(), fragment_id=250, clock=clock, name="vehicle", guard=sg)
    v = Link(config=LinkConfig(), fragment_id=250, clock=clock, name="surface", guard=rg,
             on_payload=got.append)
    s.add_channel(FEEDBACK_KEY_BASE + 30, LinkPolicy(queue="latest"))
    feedback = pack_items([0, 30, 5, 0.25])
    assert sg.overhead(FEEDBACK_KEY_BASE + 30) > 0          # weighed with its protection
    assert s.offer(FEEDBACK_KEY_BASE + 30, feedback)
    frames = carry(s, v)
    assert len(frames) == 1 and feedback not in frames[0]
    assert got == [feedback] and rg.stats()["verified"] == 1 and rg.stats()["dropped"] == 0
