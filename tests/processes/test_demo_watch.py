"""The demo watches the processes that must run throughout (bridges, vehicles) while it waits
for its operators (uwgen/demo/processes.py `wait_for`): one that ends early stops the demo at
once with its last words, instead of operators timing out call after call."""
from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from uwgen.demo.processes import Proc, ended_early, stop_all, wait_for


def child(tmp_path, name: str, code: str) -> Proc:
    return Proc(name, [sys.executable, "-c", code], dict(os.environ), tmp_path, relay=False)


def test_a_bridge_that_exits_early_is_reported_at_once_with_its_last_line(tmp_path):
    operator = child(tmp_path, "operator", "import time; time.sleep(30)")
    bridge = child(tmp_path, "bridge_surface",
                   "import sys; print('uwgen bridge: generated/x is stale: build it again'); sys.exit(2)")
    started = time.monotonic()
    try:
        dead = wait_for([operator], 30.0, [bridge], poll=0.05)
    finally:
        stop_all([bridge, operator])
    assert dead is bridge
    assert time.monotonic() - started < 15.0
    said = ended_early(dead)
    assert "bridge_surface ended early (exit 2)" in said
    assert "generated/x is stale: build it again" in said


def test_operators_that_finish_while_bridges_run_end_the_wait_with_none(tmp_path):
    operator = child(tmp_path, "operator", "pass")
    bridge = child(tmp_path, "bridge_vehicle", "import time; time.sleep(30)")
    try:
        assert wait_for([operator], 30.0, [bridge], poll=0.05) is None
    finally:
        codes = stop_all([bridge, operator])
    assert codes["operator"] == 0


def test_operators_still_running_at_the_timeout_raise_timeout_expired(tmp_path):
    operator = child(tmp_path, "operator", "import time; time.sleep(30)")
    try:
        with pytest.raises(subprocess.TimeoutExpired):
            wait_for([operator], 0.3, [], poll=0.05)
    finally:
        stop_all([operator])
