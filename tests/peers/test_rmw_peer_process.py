"""The peer as a process on a DESERT-like socket: discovery, publishing, serving, calling.

The test plays DESERT's side of the socket by hand, and reads the peer's beacons with
uwgen's own decoder (the other direction of the cross-check).
"""
from __future__ import annotations

import json
import os
import queue
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

import rmw_desert_peer as peer
from uwgen import tether
from uwgen.interop.beacons import Beacon, Entity, decode_beacon, encode_beacon

PEER = Path(__file__).with_name("rmw_desert_peer.py")
TABLE = {"/discovery": 1, "/discovery_request": 2, "/chatter": 4, "/set_bool": 13}
DEADLINE = 10.0


class FakeDesert:
    """One accepted peer connection, with frame hunting and the peer's JSON lines."""

    def __init__(self, tmp_path: Path, *args: str):
        conf = tmp_path / "ros_allowed_topics.conf"
        conf.write_text(json.dumps({"topics": TABLE}))
        self.server = socket.create_server(("127.0.0.1", 0))
        self.server.settimeout(DEADLINE)
        env = dict(os.environ, DESERT_PORT=str(self.server.getsockname()[1]),
                   ROS_ALLOWED_TOPICS_CONFIG=str(conf))
        self.proc = tether.popen([sys.executable, str(PEER), "--linger", "0", *args],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                 env=env)
        self.lines: queue.Queue = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()
        self.conn, _ = self.server.accept()
        self.conn.settimeout(DEADLINE)
        self.hunter = peer.FrameHunter()
        self.pending: list[bytes] = []

    def _pump(self):
        for line in self.proc.stdout:
            self.lines.put(json.loads(line))
        self.lines.put(None)

    def send(self, payload: bytes) -> None:
        self.conn.sendall(peer.frame(payload))

    def payload(self) -> bytes:
        while not self.pending:
            data = self.conn.recv(4096)
            assert data, "peer closed the socket"
            self.pending += self.hunter.feed(data)
        return self.pending.pop(0)

    def event(self, name: str) -> dict:
        end = time.monotonic() + DEADLINE
        while time.monotonic() < end:
            item = self.lines.get(timeout=DEADLINE)
            assert item is not None, f"peer exited before '{name}': {self.proc.stderr.read()}"
            if item["event"] == name:
                return item
        raise AssertionError(f"no '{name}' event")

    def close(self) -> int:
        self.conn.close()
        self.server.close()
        try:
            return self.proc.wait(timeout=DEADLINE)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()


@pytest.fixture
def desert_factory(tmp_path):
    made = []

    def make(*args):
        made.append(FakeDesert(tmp_path, *args))
        return made[-1]
    yield make
    for d in made:
        if d.proc.poll() is None:
            d.proc.kill()
            d.proc.wait()


def test_publisher_and_server_peer_speaks_rmw_desert_discovery(desert_factory):
    d = desert_factory("--node", "talker", "--pub", "/chatter=std_msgs/msg/String",
                       "--data", '/chatter={"data": "hello"}', "--pub-when-subscribed",
                       "--serve", "/set_bool=std_srvs/srv/SetBool",
                       "--data", '/set_bool={"success": true, "message": "ok"}', "--duration", "8")
    assert d.payload() == b"\x00\x02"   # one discovery request at start
    first = [decode_beacon(d.payload()) for _ in range(2)]
    assert [(b.node_name, b.entity, b.topic, b.type_name, b.disconnect) for b in first] == [
        ("talker", Entity.PUBLISHER, "/chatter", "std_msgs__msg/String", False),
        ("talker", Entity.SERVICE, "/set_bool", "std_srvs__srv/SetBool_Response", False)]

    d.send(b"\x00\x02")                 # a discovery request: all beacons again
    assert [decode_beacon(d.payload()) for _ in range(2)] == first

    d.send(encode_beacon(Beacon("listener", "/", Entity.SUBSCRIBER, bytes(16), "/chatter",
                                "std_msgs__msg/String")))
    assert d.payload() == bytes.fromhex("0004") + b"\x65hello"

    d.send(bytes.fromhex("020D190309F5"))       # request data=true, seq 777
    assert d.payload() == bytes.fromhex("030D190309F5626F6B")
    assert d.event("request")["data"] == {"data": True}

    d.send(bytes.fromhex("001863F5"))           # unknown id 99: ignored
    d.send(bytes.fromhex("0104"))               # kind 1 would kill rmw_desert: reported
    error = d.event("error")
    assert error["fatal"] and "kind 1" in error["reason"]
    d.send(bytes.fromhex("020D0501"))           # native bool: refused, not misread
    assert "F4/F5" in d.event("error")["reason"]

    assert d.close() == 1                       # errors were seen
    summary = d.event("summary")
    assert summary["ignored_ids"] == 1 and summary["errors"] == 2
    assert summary["requests_heard"] == 1 and summary["published"] == {"/chatter": 1}


def test_client_peer_waits_for_the_service_beacon_and_takes_the_matching_seq(desert_factory):
    d = desert_factory("--node", "caller", "--call", "/set_bool=std_srvs/srv/SetBool",
                       "--data", '/set_bool={"data": true}', "--wait-for-service",
                       "--until-done", "--seed", "3", "--duration", "8")
    assert d.payload() == b"\x00\x02"
    client = decode_beacon(d.payload())
    assert (client.entity, client.type_name) == (Entity.CLIENT, "std_srvs__srv/SetBool_Request")

    d.send(encode_beacon(Beacon("server", "/", Entity.SERVICE, bytes(16), "/set_bool",
                                "std_srvs__srv/SetBool_Response")))
    request = peer.read_items(d.payload())
    assert [i.value for i in request[:2]] == [2, 13] and request[3].value is True
    seq = request[2].value
    assert 0 <= seq <= 999
    wrong = (seq + 1) % 1000
    d.send(bytes.fromhex("030D") + peer.cbor_int(wrong) + bytes.fromhex("F460"))
    assert d.event("stray_response")["seq"] == wrong
    d.send(bytes.fromhex("030D") + peer.cbor_int(seq) + bytes.fromhex("F562") + b"ok")
    response = d.event("response")
    assert response["seq"] == seq and response["data"] == {"success": True, "message": "ok"}
    gone = decode_beacon(d.payload())           # disconnect beacon as it exits
    assert gone.disconnect and gone.gid == client.gid and gone.topic == ""
    assert d.close() == 0
    assert d.event("summary")["ok"] is True
