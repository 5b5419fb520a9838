"""The per-packet seal of wire format 2 (wire-format.md section 12.2): one tag per packet, what it
protects, and what it costs."""
from __future__ import annotations

from uwgen.runtime.wire import envelope as env
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.codec import pack_items
from uwgen.runtime.link.hooks import PacketHooks, join_hooks
from uwgen.security.guard import SYNC_EVERY
from uwgen.security.packet_seal import MAX_OVERHEAD, PacketSeal

from .helpers import KEY, WALL0, config, log_line, request, twist
from .packets import FRAGMENT_ID, Side, surface, vehicle


def plain_size(*payloads: bytes) -> int:
    """Bytes of the unsealed envelope of `payloads` (P, W and the messages)."""
    return len(env.Envelope(1, 0, tuple(env.from_v1(p) for p in payloads)).encode())


def test_one_packet_mixes_encrypted_signed_and_service_messages_under_one_tag():
    s, v = surface(), vehicle()
    payloads = (twist(0.5), log_line("readable"), request(7))
    data = s.send(*payloads)
    assert v.receive(data) == list(payloads)
    assert twist(0.5)[2:] not in data                       # cmd_vel (encrypt) is not readable
    assert log_line("readable")[2:] in data                 # the log line (sign) is
    assert env.decode(data).tag == data[-8:]


def test_a_packet_costs_the_tag_and_a_sync_packet_13_bytes_more():
    s, v = surface(), vehicle()
    sizes = []
    for i in range(2 * SYNC_EVERY):
        data = s.send(twist(float(i)))
        assert v.receive(data) == [twist(float(i))]
        sizes.append(len(data) - plain_size(twist(float(i))))
    sync = [i for i, extra in enumerate(sizes) if extra == 8 + 13]
    assert sync == [0, 1, 2, SYNC_EVERY] and sizes.count(8) == len(sizes) - 4
    assert MAX_OVERHEAD == 8 + 13 + 2


def test_every_byte_changed_is_refused():
    s, v = surface(), vehicle()
    assert v.receive(s.send(twist(1.0))) == [twist(1.0)]      # v knows s's epoch
    data = s.send(twist(2.0), log_line("x"))
    for i in range(len(data)):
        for flip in (0x01, 0x80):
            forged = bytearray(data)
            forged[i] ^= flip
            assert v.receive(bytes(forged)) == [], (i, flip)
    assert v.receive(data) == [twist(2.0), log_line("x")]     # the genuine one still goes through
    assert v.stats()["verified"] == 2


def test_a_sync_part_added_to_a_recorded_packet_breaks_its_tag():
    s, v = surface(), vehicle()
    for i in range(4):
        assert v.receive(s.send(twist(float(i)))) == [twist(float(i))]
    plain = env.decode(s.send(twist(9.0)))                    # number 4: no sync part
    assert plain.sync is None
    epoch = bytes.fromhex(s.stats()["epoch"])
    from dataclasses import replace

    from uwgen.runtime.delivery.freshness import stamp
    forged = replace(plain, sync=env.Sync(epoch, 0), time=stamp(WALL0)).encode()
    w = ManualClock(WALL0)
    fresh = vehicle(wall=w)                                   # a receiver with no state at all
    assert fresh.receive(forged) == [] and fresh.stats()["bad_tag"] + fresh.stats()["before_start"] == 1
    assert v.receive(forged) == [] and v.stats()["bad_tag"] == 1


def test_an_unsealed_packet_and_a_packet_of_another_key_are_refused():
    v = vehicle()
    plain = env.Envelope(1, 0, (env.from_v1(twist(1.0)),)).encode()
    other = surface(key=bytes(32))
    assert v.receive(plain) == [] and v.receive(other.send(twist(1.0))) == []
    st = v.stats()
    assert (st["unprotected"], st["bad_tag"], st["verified"]) == (1, 1, 0)


def test_reflected_and_unknown_senders_are_counted():
    s, v = surface(), vehicle()
    own = vehicle()
    assert v.receive(own.send(twist(1.0))) == []              # its own sender id, sent back
    stranger = Side(PacketSeal(KEY, config(9, 2, "vehicle")), 9)
    assert v.receive(stranger.send(twist(1.0))) == []
    assert (v.stats()["reflected"], v.stats()["unknown_sender"]) == (1, 1)


def test_received_hooks_see_only_admitted_envelopes():
    s = surface()
    seen = []
    reliability = PacketHooks(received=lambda e, now: seen.append(e.number))
    v_seal = vehicle().seal
    rx = Side(v_seal, 2)
    rx.unpacker.hooks = join_hooks(reliability, v_seal.hooks())
    genuine = s.send(twist(1.0))
    forged = genuine[:-1] + bytes([genuine[-1] ^ 1])
    for data in (forged, genuine, genuine):                  # forged, genuine, replayed
        rx.receive(data)
    assert seen == [0]


def test_a_time_part_older_than_the_max_age_is_stale():
    # Reliability stamps T on packets that carry messages with a max age; the seal
    # authenticates it and refuses a packet whose T is too old.
    wall = ManualClock(WALL0)
    s, v = surface(), vehicle(wall=wall)
    assert v.receive(s.send(twist(0.0))) == [twist(0.0)]
    from uwgen.runtime.delivery.freshness import stamp
    stamping = PacketHooks(parts=lambda now: {"time": stamp(WALL0)})
    s.packer.hooks = join_hooks(stamping, s.seal.hooks())
    for _ in range(3):                                        # past the first sync packets
        assert v.receive(s.send(twist(1.0))) == [twist(1.0)]
    held = s.send(twist(2.0))
    wall.advance(200.0)
    assert v.receive(held) == [] and v.stats()["stale"] == 1


def test_sync_packets_are_numbered_across_an_epoch_change():
    s, v = surface(epoch_numbers=4096), vehicle()
    numbers = []
    hooks = s.packer.hooks
    s.packer.hooks = PacketHooks(**{**hooks.__dict__, "sent": lambda n, picked, now: numbers.append(n)})
    for i in range(4096 + 5):
        assert v.receive(s.send(log_line(str(i)))) == [log_line(str(i))]
    assert numbers == list(range(4096 + 5))                  # monotonic for reliability
    assert s.seal.session.epochs_started == 2 and v.stats()["epochs_seen"] == 2


def test_a_flood_of_forged_packets_is_counted_and_logged_once(caplog):
    import logging
    s, v = surface(), vehicle()
    assert v.receive(s.send(twist(0.0))) == [twist(0.0)]
    genuine = s.send(twist(1.0))
    with caplog.at_level(logging.WARNING, logger="uwgen.security"):
        for k in range(200):
            forged = bytearray(genuine)
            forged[-1 - k % 8] ^= 1 + k // 8
            assert v.receive(bytes(forged)) == []
    assert v.stats()["bad_tag"] == 200
    lines = [r for r in caplog.records if "dropped a packet" in r.getMessage()]
    assert len(lines) == 1 and "sender 1" in lines[0].getMessage()
    assert v.receive(genuine) == [twist(1.0)]


def test_the_surface_keeps_replay_state_per_vehicle_across_three_vehicles():
    # Three vehicles seal with the same packet numbers; the surface admits each, and a replay
    # is refused for the vehicle whose packet it repeats, never for the others.
    from uwgen.security.guard import GuardConfig
    from .helpers import FINGERPRINTS, MODES
    ids = {"surface": 1, "auv1": 2, "auv2": 3, "auv3": 4}

    def side(name):
        peers = {i: n for n, i in ids.items() if n != name}
        cfg = GuardConfig("demo", ids[name], peers, dict(MODES), dict(FINGERPRINTS))
        seal = PacketSeal.for_key(KEY, cfg, None, clock=ManualClock(), wall=ManualClock(WALL0),
                                  name=name, fragment_id=FRAGMENT_ID)
        return Side(seal, ids[name])

    surface_side = side("surface")
    vehicles = [side(n) for n in ("auv1", "auv2", "auv3")]
    sent = {n: [s.send(twist(float(10 * k + i))) for i in range(3)]
            for k, (n, s) in enumerate(zip(("auv1", "auv2", "auv3"), vehicles))}
    for i in range(3):
        for k, n in enumerate(("auv1", "auv2", "auv3")):
            assert surface_side.receive(sent[n][i]) == [twist(float(10 * k + i))]
    assert surface_side.receive(sent["auv2"][1]) == []          # a replay of auv2's packet
    assert surface_side.receive(vehicles[2].send(twist(99.0))) == [twist(99.0)]   # auv3 goes on
    assert surface_side.receive(vehicles[0].send(twist(98.0))) == [twist(98.0)]   # so does auv1
    stats = surface_side.stats()
    assert stats["verified"] == 11 and sum(v for k, v in stats.items() if "replay" in k) == 1
