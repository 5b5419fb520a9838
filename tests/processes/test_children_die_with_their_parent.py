"""A process uwgen starts never outlives the process that started it (uwgen/tether.py).

An interrupted test run once left a demo's bridges and vehicle running; they shared the next
demo's ROS graph. Here a parent starts children, is SIGKILLed (it runs no clean-up of its
own), and its tethered children must stop, by SIGTERM (so they stop in order), while an
untethered sibling started the same way lives on: the difference is the tether.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from uwgen import tether

ROOT = Path(__file__).resolve().parents[2]
STOP_BOUND = 30.0     # generous: SIGTERM arrives at once, Python needs a moment to stop

# A child that says when its SIGTERM handler is in place, and what stopped it.
CHILD = """
import pathlib, signal, sys, time
mark = pathlib.Path(sys.argv[1])
def on_term(*_):
    mark.write_text("stopped by SIGTERM")
    sys.exit(0)
signal.signal(signal.SIGTERM, on_term)
mark.write_text("ready")
time.sleep(120)      # an orphan of an interrupted test run does not stay forever
"""

# A parent that starts one child with `spawn` and one with plain subprocess.Popen, prints
# their pids once both are ready, and waits to be killed.
PARENT = """
import pathlib, subprocess, sys, time
CHILD, tethered_mark, plain_mark, out = sys.argv[1:5]
child = lambda mark: [sys.executable, "-c", CHILD, mark]
{spawn}
plain = subprocess.Popen(child(plain_mark), stdout=subprocess.DEVNULL)
marks = [pathlib.Path(tethered_mark), pathlib.Path(plain_mark)]
while not all(m.exists() and m.read_text() == "ready" for m in marks):
    time.sleep(0.05)
print(tethered.pid, plain.pid, flush=True)
sys.stdin.read()
"""

SPAWNERS = {
    "tether.popen": "from uwgen import tether\n"
                    "tethered = tether.popen(child(tethered_mark), stdout=subprocess.DEVNULL)",
    "the demo's Proc": "from uwgen.demo.processes import Proc\n"
                       "import os\n"
                       "tethered = Proc('child', child(tethered_mark), dict(os.environ),"
                       " pathlib.Path(out), relay=False).proc",
}


def alive(pid: int) -> bool:
    """Running (a zombie waiting for its new parent to reap it counts as ended)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def wait_ended(pid: int, bound: float) -> bool:
    deadline = time.monotonic() + bound
    while alive(pid):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


@pytest.mark.skipif(not tether.LINUX, reason="PR_SET_PDEATHSIG is Linux's")
@pytest.mark.timeout(90)
@pytest.mark.parametrize("spawner", list(SPAWNERS))
def test_a_sigkilled_parents_tethered_child_stops_by_sigterm(tmp_path, spawner):
    tethered_mark, plain_mark = tmp_path / "tethered", tmp_path / "plain"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    parent = subprocess.Popen(
        [sys.executable, "-c", PARENT.format(spawn=SPAWNERS[spawner]), CHILD,
         str(tethered_mark), str(plain_mark), str(tmp_path)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env, cwd=ROOT)
    pids: list[int] = []
    try:
        pids = [int(p) for p in parent.stdout.readline().split()]
        assert len(pids) == 2, "the parent did not start its children"
        tethered_pid, plain_pid = pids
        parent.kill()
        parent.wait(10)
        assert wait_ended(tethered_pid, STOP_BOUND), "the tethered child outlived its parent"
        assert tethered_mark.read_text() == "stopped by SIGTERM"
        # The control: the same child without the tether is still running.
        assert alive(plain_pid) and plain_mark.read_text() == "ready"
    finally:
        if parent.poll() is None:
            parent.kill()
        parent.wait(10)
        for pid in pids:
            if alive(pid):
                os.kill(pid, signal.SIGKILL)


@pytest.mark.skipif(not tether.LINUX, reason="PR_SET_PDEATHSIG is Linux's")
def test_a_child_whose_parent_died_before_the_tether_runs_nothing():
    # The tether checks that its parent is still the one that started it: one that died
    # between fork and prctl would send no signal. Here the expected parent is another pid.
    not_the_parent = os.getpid() + 1
    res = subprocess.run([sys.executable, "-I", "-S", tether.__file__, str(not_the_parent),
                          sys.executable, "-c", "print('ran')"], capture_output=True, text=True,
                         timeout=30)
    assert res.returncode == -signal.SIGTERM and res.stdout == ""


def test_a_tethered_command_runs_as_given(tmp_path):
    res = tether.run(["sh", "-c", 'echo "$0 $1 $PWD $X"; exit 3', "a b", "c"], cwd=tmp_path,
                     env=dict(os.environ, X="x"), capture_output=True, text=True, timeout=30)
    assert res.returncode == 3 and res.stdout == f"a b c {tmp_path} x\n"


def test_a_missing_command_raises_as_subprocess_does():
    with pytest.raises(FileNotFoundError):
        tether.popen(["uwgen-no-such-program"])
