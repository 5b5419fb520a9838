"""Both bridges secured, over the emulator, with a third DESERT node whose client forges.

The emulator serves one client per port, so the forger gets in as a third acoustic node
(`forger`, sending to the vehicle): what it writes reaches the vehicle's DESERT node
over the (emulated) water, exactly as a stranger's modem would. The links speak wire format
2, one tag per packet (docs/wire-format.md section 12.2). The forger writes a cmd_vel
in the clear (an envelope with [0, 4, Twist], x = 1007), packets sealed under another
key while claiming the surface's sender id, packets with random tags, and replays of packets
the surface really sent. None reaches ROS; the real commands do, each once.
"""
from __future__ import annotations

import random
import socket
import time
from contextlib import contextmanager

import pytest
from geometry_msgs.msg import Twist
from std_srvs.srv import SetBool

from uwgen.emulator import NodeSpec, Scenario, run_emulator
from uwgen.runtime.wire.codec import load_items, pack_items
from uwgen.runtime.wire import envelope as env
from uwgen.runtime.wire.envelope import Envelope, from_v1
from uwgen.runtime.wire.framing import encode_frame
from uwgen.runtime.wire.heads import Heads
from uwgen.security import packetwire, wire
from uwgen.security.guard import GuardConfig
from uwgen.security.packet_seal import PacketSeal

from bridge.fakes import wait_for
from bridge.harness import ros_sides

from .conftest import Net, build_package

MANIFEST = """\
network: e2esec
package: uwgen_e2esec
fragment_id: 250
security: {mode: encrypt, key_file: net.key}
sides:
  surface: {port: 4000, sender_id: 1, link: {max_read_length: 64, period: 0.05}}
  vehicle: {port: 4001, sender_id: 2, link: {max_read_length: 64, period: 0.05}}
topics:
  - {name: /cmd_vel, id: 4, type: geometry_msgs/msg/Twist, publisher: surface, queue: fifo, depth: 8}
  - {name: /log, id: 7, type: std_msgs/msg/String, publisher: vehicle, security: sign}
services:
  - {name: /enable, id: 20, type: std_srvs/srv/SetBool, server: vehicle, timeout: 3}
"""


def build(tmp_path_factory, manifest_text: str, package: str):
    return build_package(tmp_path_factory.mktemp(package),
                         manifest_text.replace("package: uwgen_e2esec", f"package: {package}"),
                         package, keygen=True)


@pytest.fixture(scope="module")
def secure_package(tmp_path_factory):
    return build(tmp_path_factory, MANIFEST, "uwgen_e2esec")


@pytest.fixture(scope="module")
def schema_package(tmp_path_factory):
    """The same network with schema announcements on (wire-format.md section 10)."""
    return build(tmp_path_factory, MANIFEST.replace("fragment_id: 250\n",
                                                    "fragment_id: 250\nschema_id: 249\n"),
                 "uwgen_e2esecschema")


@contextmanager
def secured_network(package):
    scen = Scenario(nodes=[NodeSpec("surface", position=(0.0, 0.0, 0.0), dest="vehicle"),
                           NodeSpec("vehicle", position=(30.0, 0.0, 0.0), dest="surface"),
                           NodeSpec("forger", position=(15.0, 10.0, 0.0), dest="vehicle"),
                           NodeSpec("forger_s", position=(15.0, -10.0, 0.0), dest="surface")],
                    period=0.05, max_read_length=64, bitrate=48000.0, seed=9)
    with run_emulator(scen) as emu, ros_sides("surface", "vehicle") as sides:
        net = Net(package, emu, sides, 0.05, 64)
        net.start_bridge("surface")
        net.start_bridge("vehicle")
        yield net


def tap(link, prefix: bytes, tag_bytes: int = 8) -> list[bytes]:
    """Record the packets (sealed envelopes) the link writes that carry a message of `prefix`
    (kind and id; the ids of a sealed packet stay readable): what an eavesdropper on the water
    hears of them."""
    heard: list[bytes] = []
    original = link.connection._source                 # the packer's next_packet
    kind, ident = prefix

    def next_packet(*args, **kwargs):
        data = original(*args, **kwargs)
        if data is not None and any((m.kind, m.id) == (kind, ident)
                                    for m in env.decode(data, tag_bytes).messages):
            heard.append(data)
        return data
    link.connection._source = next_packet
    return heard


def tap_payloads(link, prefix: bytes) -> list[bytes]:
    """Record the payloads starting with `prefix` that the link's scheduler hands to its packer,
    before they are sealed (what only the sender knows: a service seq, an action handle)."""
    taken: list[bytes] = []
    original = link.scheduler.next_payload

    def next_payload(*args, **kwargs):
        picked = original(*args, **kwargs)
        if picked is not None and picked[1].startswith(prefix):
            taken.append(picked[1])
        return picked
    link.scheduler.next_payload = next_payload
    return taken


def on_air(payload: bytes) -> bytes:
    """The frame a forger writes: one unsealed envelope holding the payload's message."""
    return encode_frame(Envelope(sender=1, number=0, messages=(from_v1(payload),)).encode())


def stranger(sender: int, peer: int, ident: int, payload: bytes, count: int) -> list[bytes]:
    """`count` packets carrying `payload`, sealed under a key that is not the network's, in
    the name of `sender`."""
    seal = PacketSeal(bytes(range(32)), GuardConfig("e2esec", sender, {peer: "x"}, {ident: "encrypt"}),
                      name="stranger")
    hooks = seal.hooks()
    out = []
    for _ in range(count):
        hooks.next_overhead(0.0)
        number = hooks.number()
        e = Envelope(sender, number % env.NUMBER_MOD, (from_v1(payload),), **hooks.parts(0.0))
        out.append(hooks.seal(e))
    return out


CMD_VEL = bytes([0, 4])         # kind 0, id 4
REQUEST = bytes([2, 20])        # kind 2, id 20


def security(net, side):
    return net.bridges[side].status()["security"]


def cmd_vel_ends(net):
    """The vehicle's received cmd_vel list, the surface's publisher, and what the surface's
    link sends of cmd_vel (a tap), once both bridges are up and the publisher is matched."""
    got: list[Twist] = []
    net.vehicle.node("sim").create_subscription(Twist, "/cmd_vel", got.append, 50)
    pub = net.surface.node("op").create_publisher(Twist, "/cmd_vel", 10)
    heard = tap(net.bridges["surface"].link, CMD_VEL, net.package.MANIFEST.security.tag_bytes)
    wait_for(lambda: net.connected()
             and pub.get_subscription_count(), what="secured bridges up")
    return got, pub, heard


def test_forged_cmd_vel_never_reaches_ros(secure_package, tmp_path):
    with secured_network(secure_package) as net:
        got, pub, heard = cmd_vel_ends(net)

        for k in range(5):                                # the real operator
            pub.publish(Twist(linear=Twist().linear.__class__(x=0.1 * (k + 1))))
            time.sleep(0.1)
        wait_for(lambda: len(got) == 5, timeout=10, what="the real commands")
        assert heard

        rng = random.Random(5)
        plain = pack_items([0, 4, 1007.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        before = security(net, "vehicle")
        forged = ([on_air(plain)] * 5
                  + [encode_frame(p) for p in stranger(1, 2, 4, plain, 5)]   # another key, surface's id
                  + [encode_frame(h[:-8] + rng.randbytes(8)) for h in heard]  # random tags
                  + [encode_frame(h) for h in heard])                       # replays of real packets
        with socket.create_connection(("127.0.0.1", net.emu.port("forger"))) as forger:
            for frame in forged:
                forger.sendall(frame)
                time.sleep(0.06)                             # about one packet per period
            wait_for(lambda: security(net, "vehicle")["dropped"] - before["dropped"] >= len(forged),
                     timeout=15, what="every forged frame counted")
        time.sleep(0.3)                                      # anything published would be here by now
        sec = {k: v - before[k] for k, v in security(net, "vehicle").items() if isinstance(v, int)}
        assert sec["dropped"] == len(forged) == 10 + 2 * len(heard)
        assert (sec["unprotected"], sec["replay"]) == (5, len(heard))
        assert sec["bad_tag"] + sec["unsynced"] == 5 + len(heard)
        assert len(got) == 5 and all(m.linear.x < 1 for m in got)
        assert net.bridges["vehicle"].status()["topics"]["/cmd_vel"]["published"] == 5


def test_secured_service_is_answered_once_and_only_when_authentic(secure_package):
    with secured_network(secure_package) as net:
        calls = net.serve_enable()
        client = net.surface.node("caller").create_client(SetBool, "/enable")
        assert client.wait_for_service(timeout_sec=5.0)
        heard = tap(net.bridges["surface"].link, REQUEST)
        wait_for(lambda: net.connected()
                 and net.bridges["vehicle"]._served[20][1].service_is_ready(), what="server visible")
        future = client.call_async(SetBool.Request(data=True))
        wait_for(future.done, what="the secured response")
        assert future.result().success and calls == [True]
        with socket.create_connection(("127.0.0.1", net.emu.port("forger"))) as forger:
            forger.sendall(encode_frame(heard[0]))       # the request's packet, replayed
            forger.sendall(on_air(pack_items([2, 20, 99, True])))   # a request in the clear
            wait_for(lambda: security(net, "vehicle")["dropped"] >= 2, what="forgeries counted")
        time.sleep(0.3)
        assert calls == [True]
        sec = security(net, "vehicle")
        assert (sec["replay"], sec["unprotected"]) == (1, 1)
        assert net.bridges["vehicle"].status()["services"]["/enable"]["requests"] == 1


def test_frames_replayed_after_a_bridge_restart_are_rejected(secure_package):
    with secured_network(secure_package) as net:
        got, pub, heard = cmd_vel_ends(net)
        for k in range(3):
            pub.publish(Twist(linear=Twist().linear.__class__(x=0.1 * (k + 1))))
            time.sleep(0.1)
        wait_for(lambda: len(got) == 3, what="the real commands")

        old = net.bridges["vehicle"]                      # the vehicle's bridge restarts
        net.vehicle.executor.remove_node(old)
        old.close()
        new = net.start_bridge("vehicle")
        # up, and its clock exchange with the surface over (its probes and the surface's
        # answers would collide with the replays on the water)
        wait_for(lambda: new.link.stats()["connected"] and new.reliability.offsets.peers(),
                 what="restarted vehicle bridge up")
        time.sleep(0.5)
        with socket.create_connection(("127.0.0.1", net.emu.port("forger"))) as forger:
            for frame in heard:
                forger.sendall(encode_frame(frame))
                time.sleep(0.06)
            wait_for(lambda: new.status()["security"]["dropped"] >= len(heard), what="replays counted")
        sec = new.status()["security"]
        # the restarted bridge kept nothing, yet takes no packet sealed before it started: the
        # sync packets of the surface's epoch are before_start; the others are below the
        # number of the surface's sync packet that answered its start (replay, too_old), or
        # unsynced if that had not come
        refused = sum(sec[r] for r in ("before_start", "unsynced", "replay", "too_old"))
        assert refused == sec["dropped"] == len(heard)
        assert new.status()["topics"]["/cmd_vel"]["published"] == 0 and len(got) == 3
        # the operator goes on: heard from the surface's next sync frame (1 in 64, or after
        # 30 s), so it repeats the command until it is obeyed, as a joystick does
        deadline = time.monotonic() + 20
        while len(got) == 3 and time.monotonic() < deadline:
            pub.publish(Twist(linear=Twist().linear.__class__(x=0.9)))
            time.sleep(0.05)
        wait_for(lambda: len(got) >= 4, what="a new command after the restart")
        assert [round(m.linear.x, 2) for m in got[:4]] == [0.1, 0.2, 0.3, 0.9]
        assert {round(m.linear.x, 2) for m in got[4:]} <= {0.9}


def test_schema_announcements_are_signed_and_forged_ones_cannot_refuse_an_id(schema_package):
    with secured_network(schema_package) as net:
        got: list[Twist] = []
        net.vehicle.node("sim").create_subscription(Twist, "/cmd_vel", got.append, 50)
        pub = net.surface.node("op").create_publisher(Twist, "/cmd_vel", 10)
        vehicle = net.bridges["vehicle"]
        wait_for(lambda: vehicle.status()["schema"]["heard"].get("4"), timeout=10,
                 what="the surface's signed schema announcement")
        # a stranger announces another fingerprint for /cmd_vel, to make the vehicle refuse it
        forged = pack_items([0, 249, 0, 4, b"\x00\x00\x00\x00"])
        with socket.create_connection(("127.0.0.1", net.emu.port("forger"))) as forger:
            # again and again: a copy may collide with the bridges' own announcements
            deadline = time.monotonic() + 10
            while security(net, "vehicle")["unprotected"] < 3 and time.monotonic() < deadline:
                forger.sendall(on_air(forged))
                time.sleep(0.2)
        assert security(net, "vehicle")["unprotected"] >= 3
        assert vehicle.status()["schema"]["mismatched"] == {}
        wait_for(lambda: pub.get_subscription_count(), what="bridge subscribed")
        pub.publish(Twist(linear=Twist().linear.__class__(x=0.4)))
        wait_for(lambda: got, what="cmd_vel still flows")
        assert got[0].linear.x == 0.4


def test_a_forged_response_never_completes_a_call(secure_package, tmp_path):
    with secured_network(secure_package) as net:
        client = net.surface.node("caller").create_client(SetBool, "/enable")
        assert client.wait_for_service(timeout_sec=5.0)          # the surface's stand-in
        requests = tap_payloads(net.bridges["surface"].link, REQUEST)
        wait_for(net.connected, what="secured bridges up")
        future = client.call_async(SetBool.Request(data=True))  # no server on the vehicle: no answer
        wait_for(lambda: requests, what="the request on the water")
        # the seq is encrypted on the water; the forger is given it anyway
        seq = load_items(requests[0])[2]
        plain = pack_items([3, 20, seq, True, "forged"])
        with socket.create_connection(("127.0.0.1", net.emu.port("forger_s"))) as forger:
            for frame in (on_air(plain), encode_frame(stranger(2, 1, 20, plain, 1)[0])):
                forger.sendall(frame)
                time.sleep(0.1)
            wait_for(lambda: security(net, "surface")["dropped"] >= 2, what="forged responses counted")
        surface = net.bridges["surface"]
        wait_for(lambda: surface.service_counters[20].timeouts == 1, timeout=6, what="the call's timeout")
        assert not future.done()                                # no forged success reached the caller
        assert surface.service_counters[20].responses == 0
        # what the surface verified is the vehicle's own packets (its clock probes and acks)
        vehicle_sent = net.bridges["vehicle"].link.stats()["packets"]["packets_sent"]
        assert security(net, "surface")["verified"] <= vehicle_sent


ACTION = """\
actions:
  - {name: /fibonacci, id: 9, type: test_msgs/action/Fibonacci, server: vehicle,
     accept_timeout: 3, result_timeout: 10, feedback: {rate: 10}}
"""
GOAL = bytes([2, 9])            # kind 2 (request), id 9: goals and cancels


@pytest.fixture(scope="module")
def action_package(tmp_path_factory):
    """The secured network with an action: it takes the network's mode (encrypt)."""
    return build(tmp_path_factory, MANIFEST + ACTION, "uwgen_e2esecaction")


def test_a_secured_action_runs_and_forged_goals_and_cancels_never_reach_the_server(action_package):
    from .test_actions_over_emulator import FibonacciServer, ready_client, result_of, send
    assert action_package.MANIFEST.security.modes[9] == "encrypt"
    with secured_network(action_package) as net:
        real = FibonacciServer(net.vehicle.node("fibonacci_server"), step=0.2)
        heard = tap(net.bridges["surface"].link, GOAL)
        goals = tap_payloads(net.bridges["surface"].link, GOAL)
        client = ready_client(net)
        feedback: list = []
        goal_handle = send(client, 5, feedback)
        assert goal_handle.accepted
        result = result_of(goal_handle)
        assert list(result.result.sequence) == [0, 1, 1, 2, 3, 5]
        assert feedback                                        # protected feedback arrived too
        assert real.goals == [5] and heard
        served = lambda: net.bridges["vehicle"].status()["actions"]["/fibonacci"]  # noqa: E731
        wait_for(lambda: served()["results_acked"] + served()["results_told_arrived"] == 1,
                 what="the result's acknowledgement (its report's, or the client side's), "
                      "protected too")
        # known to the sender only (the reliability head's age comes first, wire-format 15.4)
        handle = load_items(Heads(aged=frozenset({9})).take(goals[0]).payload)[2]
        # the goal (handle and order) is encrypted: its packet opens only as ciphertext under
        # the surface's key (the modes are in the authenticated data), which no byte search
        # could prove
        packet = env.decode(heard[0])
        seal = net.bridges["surface"].guard
        seq = packet.number if packet.sync is None else (packet.sync.high << 12) | packet.number
        opened = packetwire.open_envelope(
            seal.session.aead, packet, seq, lambda m: seal.config.modes.get(m.id) == wire.ENCRYPT,
            lambda i: seal.config.fingerprints.get(i, b""))
        assert opened is not None
        goal = next(m for m in opened.messages if (m.kind, m.id) == (2, 9))
        assert Heads(aged=frozenset({9})).take(env.to_v1(goal)).payload == \
            pack_items([2, 9, handle, 5])
        assert goal.body not in heard[0]
        verified = security(net, "vehicle")["verified"]
        assert verified >= 1

        forged = [pack_items([2, 9, (handle + 1) % 12, 20]),  # a new goal in the clear
                  pack_items([2, 9, handle])]                  # a cancel in the clear
        with socket.create_connection(("127.0.0.1", net.emu.port("forger"))) as forger:
            for frame in [on_air(f) for f in forged] + [encode_frame(h) for h in heard]:
                forger.sendall(frame)                          # and the real goal, replayed
                time.sleep(0.06)
            wait_for(lambda: security(net, "vehicle")["dropped"] >= len(forged) + len(heard),
                     timeout=15, what="every forged goal and cancel counted")
        time.sleep(0.5)                                        # a goal let through would start by now
        sec = security(net, "vehicle")
        assert (sec["unprotected"], sec["replay"] + sec["too_old"]) == (2, len(heard))
        assert sec["verified"] == verified                    # nothing forged was taken
        assert real.goals == [5] and real.cancels == 0
        assert net.bridges["vehicle"].status()["actions"]["/fibonacci"]["goal_requests"] == 1
