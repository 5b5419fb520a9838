"""Shared fixtures of the rmw_desert interop tests."""
from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from uwgen import tether

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "msg_samples"
RMW_SAMPLE = SAMPLES / "rmw_desert"
PEER_PATH = ROOT / "tests" / "peers" / "rmw_desert_peer.py"


def load_peer():
    """The independent rmw_desert peer module (tests/peers/rmw_desert_peer.py)."""
    name = "rmw_desert_peer"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, PEER_PATH)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def start_peer(port: int, conf: Path, *args: str) -> subprocess.Popen:
    """The peer as a process on DESERT port `port` with id table `conf` (JSON lines out)."""
    env = dict(os.environ, DESERT_PORT=str(port), ROS_ALLOWED_TOPICS_CONFIG=str(conf))
    return tether.popen([sys.executable, str(PEER_PATH), *args], stdout=subprocess.PIPE,
                        stderr=subprocess.PIPE, text=True, env=env)


def peer_events(proc: subprocess.Popen, timeout: float = 30) -> list[dict]:
    """Every event the peer printed, once it exited; its summary must be the last."""
    out, err = proc.communicate(timeout=timeout)
    lines = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    assert lines and lines[-1]["event"] == "summary", err[-2000:]
    return lines


@pytest.fixture(scope="session")
def peer():
    return load_peer()


@pytest.fixture(scope="session")
def lib():
    from uwgen.idl.loader import InterfaceLibrary
    return InterfaceLibrary(folders=[SAMPLES], installed=True)


@pytest.fixture(scope="session")
def rmw_manifest(lib):
    from uwgen.manifest.loader import load_manifest
    return load_manifest(RMW_SAMPLE / "uwgen.yaml", lib)
