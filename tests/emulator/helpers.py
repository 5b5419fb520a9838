"""Helpers for the emulator tests: small scenarios and a socket reader with a deadline."""
from __future__ import annotations

import socket
import time
from pathlib import Path

import pytest

from uwgen.emulator import NodeSpec, Scenario

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "msg_samples" / "scenarios"


def two_nodes(distance: float = 1500.0, **kw) -> Scenario:
    """Nodes `a` and `b`, `distance` metres apart, sending to each other."""
    kw.setdefault("listen_jitter", 0.0)
    return Scenario(nodes=[NodeSpec("a", position=(0.0, 0.0, 0.0), dest="b"),
                           NodeSpec("b", position=(distance, 0.0, 0.0), dest="a")], **kw)


def fast_link(**kw) -> Scenario:
    """A quick real-time link for socket tests: 20 ms period, a fast modem, 30 m apart."""
    kw.setdefault("period", 0.02)
    kw.setdefault("bitrate", 200_000.0)
    return two_nodes(distance=30.0, **kw)


def recv_exactly(sock: socket.socket, n: int, timeout: float = 3.0) -> bytes:
    """Read exactly n bytes, or fail the test after `timeout` seconds."""
    deadline = time.monotonic() + timeout
    out = b""
    while len(out) < n:
        left = deadline - time.monotonic()
        if left <= 0:
            pytest.fail(f"timed out after {len(out)} of {n} bytes")
        sock.settimeout(left)
        try:
            chunk = sock.recv(n - len(out))
        except socket.timeout:
            continue
        if not chunk:
            pytest.fail(f"connection closed after {len(out)} of {n} bytes")
        out += chunk
    return out


def connect(port: int) -> socket.socket:
    s = socket.create_connection(("127.0.0.1", port), timeout=3.0)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def wait_for(predicate, timeout: float = 3.0, step: float = 0.005) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(step)
    return predicate()
