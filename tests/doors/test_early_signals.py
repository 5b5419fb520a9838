"""A SIGINT (Ctrl-C) or SIGTERM while a bridge is still starting (importing rclpy takes a
second) stops it cleanly: exit status 0, one log line, no KeyboardInterrupt traceback."""
from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from .helpers import ROOT, SAMPLES

# The child sends itself the signal at the moment rclpy starts to be imported: the place a
# Ctrl-C lands when a user gives up on a slow start, reached here without any timing guess.
HOOK = """
import importlib.abc, os, signal, sys
class SignalOnRclpy(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "rclpy":
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.{sig})
        return None
sys.meta_path.insert(0, SignalOnRclpy())
"""

ENTRIES = {
    "generated module": "from uwgen_turtle_rmw.bridge_vehicle import main\nsys.exit(main(['--port', '1']))\n",
    "uwgen bridge": ("from uwgen.cli import main\nsys.exit(main(['bridge', '-m', {manifest!r}, '--side', "
                     "'vehicle', '--package-dir', {generated!r}, '--port', '1']))\n"),
}


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("entry", sorted(ENTRIES))
def test_a_signal_while_rclpy_is_imported_stops_the_bridge_cleanly(entry, sig):
    code = HOOK.format(sig=sig) + ENTRIES[entry].format(
        manifest=str(SAMPLES / "rmw_desert" / "uwgen.yaml"), generated=str(ROOT / "generated"))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "generated"), str(ROOT)]))
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         env=env, cwd=ROOT)
    assert "Traceback" not in res.stderr and "KeyboardInterrupt" not in res.stderr, res.stderr
    assert res.returncode == 0, res.stderr
    assert "stopped before the bridge started" in res.stderr


def test_the_generated_module_exits_quietly_on_a_ctrl_c_before_the_bridge_takes_over():
    text = (ROOT / "generated" / "uwgen_turtle_rmw" / "bridge_vehicle.py").read_text()
    assert "except KeyboardInterrupt:" in text and "sys.exit(130)" in text
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "generated"), str(ROOT)]))
    # Ctrl-C while the module's main() imports uwgen's bridge (before it took SIGINT over).
    # The child first takes a terminal's SIGINT (KeyboardInterrupt): a suite started in the
    # background of a non-interactive shell runs with SIGINT ignored, inherited by children.
    res = subprocess.run([sys.executable, "-c",
                          "import importlib.abc, os, signal, sys, runpy\n"
                          "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
                          "class S(importlib.abc.MetaPathFinder):\n"
                          "    def find_spec(self, name, path=None, target=None):\n"
                          "        if name == 'uwgen.bridge.main':\n"
                          "            sys.meta_path.remove(self); os.kill(os.getpid(), signal.SIGINT)\n"
                          "        return None\n"
                          "sys.meta_path.insert(0, S())\n"
                          "runpy.run_module('uwgen_turtle_rmw.bridge_vehicle', run_name='__main__')\n"],
                         capture_output=True, text=True, timeout=60, env=env, cwd=ROOT)
    assert res.returncode == 130 and "Traceback" not in res.stderr, res.stderr
